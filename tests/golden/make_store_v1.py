"""Write the golden store of format version 1 (run once; the output is committed).

    python tests/golden/make_store_v1.py

Never re-run this to make a failing golden test pass: the golden files pin the format.
"""

import json
import os
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

import cclogfs  # noqa: E402

OUT = HERE / "store_v1"


def windows():
    """The puts: every codec, several streams, a name that looks like a path, odd JSON."""
    yield "/odom", [(i * 10_000_000, json.dumps({"x": i * 0.1, "i": i})) for i in range(150)], {"score": 3.1}, "none"
    yield "/odom", [(1_000_000_000 + i * 10_000_000, json.dumps({"x": i * 0.1, "i": i})) for i in range(30)], {"score": 3.1}, "zstd"
    yield "/tf", [(1_000_000_000, '{"a" :1.0, "b":[ ]}'), (1_000_000_001, ' "\\u00e9" ')], {}, "none"
    yield "../../etc/passwd", [(5, "NaN"), (6, "-0.0"), (6, "123456789012345678901234567890")], {"w": [1, 2]}, {"id": "lzma", "preset": 6}
    yield "/odom", [(2_000_000_000 + i, json.dumps({"x": i})) for i in range(5)], {"part": 2}, "zstd"


def main():
    if OUT.exists():
        shutil.rmtree(OUT)
    expected = []
    with cclogfs.open_store(OUT, create=True, segment_bytes=4096) as store:
        for name, messages, meta, codec in windows():
            r = store.put_window(name, messages, meta=meta, codec=codec)
            store.sync()
            expected.append({"seq": r.seq, "name": name, "meta": meta, "messages": messages})
    os.unlink(OUT / "LOCK")
    (HERE / "store_v1.expected.json").write_text(json.dumps(expected, indent=1) + "\n")


if __name__ == "__main__":
    main()
