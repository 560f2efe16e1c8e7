"""Compaction benchmark: how fast the store rewrites and drops sealed segments, against
putting the same windows in the same run.

    python -m bench compaction [--windows 600]

Rows: put (no fsync, the baseline); rewrite keeping every record (each is read and
checked, nothing written); rewrite replacing every record by itself (decode, encode, new
generation); rewrite downsampling every record to half its messages; drop_oldest until no
sealed segment is left. Each a median of 3 runs on a fresh copy of the store.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import cclogfs

from ._util import machine, odom_messages, save_json
from .store import windows_of

OPTS = dict(sync_every_ms=None, sync_every_bytes=None, segment_records=64)


def timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--windows", type=int, default=600)
    args = ap.parse_args()
    windows = windows_of(odom_messages(), count=args.windows)
    json_mb = sum(len(t) for w in windows for _, t in w) / 1e6
    work = Path(tempfile.mkdtemp())
    base = work / "base"

    def put(path):
        with cclogfs.open_store(path, create=True, **OPTS) as store:
            for w in windows:
                store.put_window("/odom", w)
            store.seal()

    rows = {"put (no fsync)": []}
    for i in range(3):
        shutil.rmtree(base, ignore_errors=True)
        rows["put (no fsync)"].append(timed(lambda: put(base)))
    steps = {
        "rewrite, keep all": lambda s: s.rewrite(lambda w: None),
        "rewrite, replace all": lambda s: s.rewrite(
            lambda w: cclogfs.Replacement(list(w.messages()), w.meta)),
        "rewrite, downsample 2x": lambda s: s.rewrite(
            lambda w: cclogfs.Replacement(list(w.messages())[::2], w.meta)),
        "drop_oldest until empty": lambda s: [None for _ in iter(s.drop_oldest, None)],
    }
    sizes = {}
    for label, step in steps.items():
        rows[label] = []
        for i in range(3):
            copy = work / f"run{i}"
            shutil.rmtree(copy, ignore_errors=True)
            shutil.copytree(base, copy)
            with cclogfs.open_store(copy, **OPTS) as store:
                before = store.disk_bytes()
                rows[label].append(timed(lambda: step(store)))
                sizes[label] = (before, store.disk_bytes())
    shutil.rmtree(work, ignore_errors=True)
    put_s = sorted(rows["put (no fsync)"])[1]
    print(f"{len(windows)} windows of 200 /odom messages ({json_mb:.1f} MB of JSON), "
          f"segments of 64 windows; {machine()}")
    print(f"{'step':26} {'median s':>9} {'windows/s':>10} {'JSON MB/s':>10} {'vs put':>7}  disk before -> after")
    result = {"machine": machine(), "windows": len(windows), "json_mb": json_mb, "rows": {}}
    for label, times in rows.items():
        secs = sorted(times)[1]
        size = sizes.get(label)
        disk = f"{size[0] / 1e6:.2f} MB -> {size[1] / 1e6:.2f} MB" if size else ""
        print(f"{label:26} {secs:9.3f} {len(windows) / secs:10.0f} {json_mb / secs:10.1f} "
              f"{put_s / secs:6.2f}x  {disk}")
        result["rows"][label] = {"median_s": secs, "windows_per_s": len(windows) / secs,
                                 "vs_put": put_s / secs, "disk_bytes": size}
    save_json("bench_compaction.json", result)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
