"""Write the golden store of format version 2 (run once; the output is committed).

    python tests/golden/make_store_v2.py

A store compaction and retention have changed: a dropped first segment (the log starts at
seq 2), a segment rewritten to generation 1 holding an AGED record (codec none, so its bytes
can be pinned), a downsampled record and a kept one, a segment rewritten twice
(generation 2), an untouched sealed segment and an active one.
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
from cclogfs.store.format import RecordFlag  # noqa: E402
from cclogfs.store import Replacement  # noqa: E402

OUT = HERE / "store_v2"
AGED = {"float_abs": 0.005, "downsampled": 2}


def odom(i, n, t0):
    return [(t0 + k * 10_000_000, json.dumps({"x": round(0.123456 * k + i, 6), "k": k})) for k in range(n)]


def replace(window):
    if window.seq == 2:  # aged: rounded and downsampled
        messages = [(t, json.dumps({"x": round(json.loads(text)["x"], 2), "k": json.loads(text)["k"]}))
                    for t, text in list(window.messages())[::2]]  # fmt: skip
        return Replacement(messages, dict(window.meta, aged=AGED), codec="none", flags=RecordFlag.AGED)
    if window.seq == 4:  # downsampled, texts exact
        return Replacement(list(window.messages())[1:], window.meta, codec="zstd")
    if window.seq == 6:
        return Replacement(list(window.messages()), dict(window.meta, pass_=1))
    return None


def main():
    if OUT.exists():
        shutil.rmtree(OUT)
    with cclogfs.open_store(OUT, create=True, codec="zstd", segment_records=2, sync_every_ms=None) as store:
        for i in range(9):
            name = "/tf" if i % 3 == 2 else "/odom"
            store.put_window(name, odom(i, 6, 1_000_000_000 * i), meta={"i": i})
        store.rewrite(replace)
        store.rewrite(lambda w: Replacement(list(w.messages()), dict(w.meta, pass_=2)) if w.seq == 6 else None)
        store.drop_oldest()
        expected = {
            "first_seq": store.first_seq,
            "dropped": store.dropped(),
            "gens": {s["first_seq"]: s.get("gen", 0) for s in store.manifest["segments"]},
            "windows": [{"seq": w.seq, "name": w.name, "meta": w.meta, "flags": w.flags, "aged": w.aged,
                         "codec": w.codec_config, "messages": [list(m) for m in w.messages()]}
                        for w in sorted(store.query(), key=lambda w: w.seq)],  # fmt: skip
        }
    os.unlink(OUT / "LOCK")
    (HERE / "store_v2.expected.json").write_text(json.dumps(expected, indent=1) + "\n")


if __name__ == "__main__":
    main()
