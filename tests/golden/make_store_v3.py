"""Write the golden store of format version 3 (run once; the output is committed).

    python tests/golden/make_store_v3.py

Records of version 2 (each carries its segment's synced length), a sealed segment, and an
active one closed cleanly (the manifest's `checkpoint`); codec none, so bytes are pinned.
Never re-run this to make a failing golden test pass: the golden files pin the format.
"""

import json
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

import cclogfs  # noqa: E402

OUT = HERE / "store_v3"


def main():
    windows = write_store(OUT)
    (HERE / "store_v3.expected.json").write_text(json.dumps(windows, indent=1) + "\n")


def write_store(out: Path) -> list[dict]:
    """The store's puts (make_store_v3_digest.py makes the same ones); its windows."""
    if out.exists():
        shutil.rmtree(out)
    with cclogfs.open_store(out, create=True, codec="none", segment_records=3, sync_every_ms=None) as store:
        for i in range(5):
            name = "/tf" if i % 2 else "/odom"
            store.put_window(name, [(1_000_000_000 * i + k, json.dumps({"i": i, "k": k})) for k in range(3)],
                             meta={"i": i})  # fmt: skip
            if i in (0, 3):
                store.sync()
        windows = [{"seq": w.seq, "name": w.name, "meta": w.meta, "messages": [list(m) for m in w.messages()]}
                   for w in sorted(store.query(), key=lambda w: w.seq)]  # fmt: skip
    (out / "LOCK").unlink()
    (out / "RESERVE").unlink(missing_ok=True)  # space set aside, not data (FORMAT.md, "Reserve")
    return windows


if __name__ == "__main__":
    main()
