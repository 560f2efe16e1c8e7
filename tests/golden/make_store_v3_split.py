"""Write the golden store of split windows (run once; the output is committed).

    python tests/golden/make_store_v3_split.py

Format version 3 with record flag `PART` (issue 16): windows over the record limit stored as
consecutive records, every part but the last flagged PART. The record limit is lowered to
300 bytes here so that the parts are small; codec none, so their bytes are pinned. A split
window in a sealed segment (the writer seals only after a put's last part, so it holds all
five parts though its limit is four records), a whole window, and a split window in the
active segment closed cleanly (the manifest's `checkpoint`).
Never re-run this to make a failing golden test pass: the golden files pin the format.
"""

import json
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

import cclogfs  # noqa: E402
from cclogfs.store import encode  # noqa: E402

OUT = HERE / "store_v3_split"


def main():
    if OUT.exists():
        shutil.rmtree(OUT)
    encode.MAX_RECORD_RAW = 300
    with cclogfs.open_store(OUT, create=True, codec="none", segment_records=4, sync_every_ms=None) as store:
        odom = [(1_000_000_000 + k * 1000 // 3, json.dumps({"k": k, "pad": "o" * (k % 7)})) for k in range(40)]
        receipts = [store.put_window("/odom", odom, meta={"window": 1})]
        receipts.append(store.put_window("/tf", [(1_000_000_500, '{"tf":1}')], meta={"window": 2}))
        tf = [(2_000_000_000 + k, json.dumps({"k": k})) for k in range(20)]
        receipts.append(store.put_window("/tf", tf, meta={"window": 3}))
        windows = [{"seq": w.seq, "name": w.name, "meta": w.meta, "flags": w.flags,
                    "messages": [list(m) for m in w.messages()]}
                   for w in sorted(store.query(), key=lambda w: w.seq)]  # fmt: skip
    (OUT / "LOCK").unlink()
    (OUT / "RESERVE").unlink()
    assert [r.records for r in receipts] == [5, 1, 2], [r.records for r in receipts]
    (HERE / "store_v3_split.expected.json").write_text(json.dumps(windows, indent=1) + "\n")


if __name__ == "__main__":
    main()
