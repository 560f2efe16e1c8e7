"""Write the golden store of format version 3 whose clean close stated the checkpoint's
`xxh3` (run once; the output is committed).

    python tests/golden/make_store_v3_digest.py

The same puts as store_v3 (its expected windows hold for this store too), written by the
version that added the checkpoint index and the digest: the active segment's `.idx` and
`checkpoint.xxh3`, the XXH3-64 of the segment's first `synced` bytes then that index file.
Never re-run this to make a failing golden test pass: the golden files pin the format.
"""

from make_store_v3 import HERE, write_store

OUT = HERE / "store_v3_digest"

if __name__ == "__main__":
    write_store(OUT)
