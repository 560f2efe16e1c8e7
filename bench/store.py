"""Store benchmark: put throughput by sync policy, query latency and crash-open time as the
store grows, and peak memory while ingesting.

    python -m bench store [--max-windows 1000000]
"""

from __future__ import annotations

import argparse
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cclogfs
from cclogfs.store.format import segment_name

from ._util import OUT, machine, median_time, odom_messages, save_json

POLICIES = {
    "group commit (200 ms / 4 MiB)": dict(sync_every_ms=200, sync_every_bytes=4 << 20),
    "fsync per put": dict(sync_every_ms=0, sync_every_bytes=None),
    "no fsync": dict(sync_every_ms=None, sync_every_bytes=None),
}


def windows_of(messages, size=200, count=150):
    """`count` windows of `size` real messages, stamps shifted so time keeps increasing."""
    span = messages[-1][0] - messages[0][0] + 1
    out = []
    for k in range(count):
        start = (k * size) % (len(messages) - size)
        shift = (k * size // len(messages) + 1) * span
        out.append([(t + shift, text) for t, text in messages[start : start + size]])
    return out


def bench_put(work: Path) -> dict:
    windows = windows_of(odom_messages())
    json_mb = sum(len(t) for w in windows for _, t in w) / 1e6
    results = {}
    for label, policy in POLICIES.items():
        def run():
            path = work / "put"
            shutil.rmtree(path, ignore_errors=True)
            with cclogfs.open_store(path, create=True, **policy) as store:
                for w in windows:
                    store.put_window("/odom", w)
        secs = median_time(run, runs=5)
        results[label] = {"windows_per_s": len(windows) / secs, "json_mb_per_s": json_mb / secs}
    base = results["fsync per put"]["windows_per_s"]
    for r in results.values():
        r["vs_fsync_per_put"] = r["windows_per_s"] / base
    return results


def bench_growth(work: Path, sizes: list[int]) -> list[dict]:
    """Tiny windows at 100 Hz; at each size, median latency of 1-second queries and open time
    after a crash (a torn record appended to the active segment)."""
    path = work / "grow"
    shutil.rmtree(path, ignore_errors=True)
    store = cclogfs.open_store(path, create=True, codec="none", sync_every_ms=None,
                               sync_every_bytes=8 << 20, segment_bytes=16 << 20)  # fmt: skip
    step, have, rows = 10_000_000, 0, []
    rng = random.Random(1)
    for size in sizes:
        for i in range(have, size):
            store.put_window("/odom", [(i * step, '{"v": %d}' % i)])
        have = size
        store.sync()
        lat = []
        for _ in range(200):
            t0 = rng.randrange(0, max(1, size * step - 1_000_000_000))
            t = time.perf_counter()
            n = sum(1 for w in store.query("/odom", t0, t0 + 1_000_000_000) for _ in w.messages())
            lat.append(time.perf_counter() - t)
        active = store.file_path(segment_name(store.active_first_seq))
        store.close()
        with open(active, "ab") as f:  # a crash mid-write: a torn record at the end
            f.write(b"CCLR\x01\x01" + b"\x07" * 50)
        opens = []
        for _ in range(5):
            t = time.perf_counter()
            store = cclogfs.open_store(path, codec="none", sync_every_ms=None, sync_every_bytes=8 << 20,
                                       segment_bytes=16 << 20)  # fmt: skip
            opens.append(time.perf_counter() - t)
            if len(opens) < 5:
                active = store.file_path(segment_name(store.active_first_seq))
                store.close()
                with open(active, "ab") as f:
                    f.write(b"CCLR\x01\x01" + b"\x07" * 50)
        rows.append({"windows": size, "segments": store.segment_count(), "windows_per_query": n,
                     "query_ms_median": 1e3 * statistics.median(lat),
                     "query_ms_p99": 1e3 * sorted(lat)[int(len(lat) * 0.99) - 1],
                     "open_after_crash_ms_median": 1e3 * statistics.median(opens)})  # fmt: skip
        print(f"  {size:>9} windows: query {rows[-1]['query_ms_median']:.3f} ms, "
              f"open after crash {rows[-1]['open_after_crash_ms_median']:.1f} ms", flush=True)
    store.close()
    return rows


RSS_CHILD = """
import sys, cclogfs
sys.path.insert(0, {root!r})
from bench.store import windows_of
from bench._util import odom_messages, peak_rss_mib
ws = windows_of(odom_messages(), count=50)
marks = {{}}
with cclogfs.open_store({path!r}, create=True, segment_bytes=8 << 20) as s:
    for i in range({n}):
        w = ws[i % len(ws)]
        shift = (i // len(ws)) * 10**12
        s.put_window("/odom", [(t + shift, m) for t, m in w])
        if i + 1 in ({n} // 10, {n}):
            marks[i + 1] = peak_rss_mib()
print(marks[{n} // 10], marks[{n}])
"""


def bench_rss(work: Path, n: int) -> dict:
    path = work / "rss"
    shutil.rmtree(path, ignore_errors=True)
    root = str(Path(__file__).resolve().parent.parent)
    out = subprocess.run([sys.executable, "-c", RSS_CHILD.format(root=root, path=str(path), n=n)],
                         capture_output=True, text=True, check=True, cwd=root).stdout.split()  # fmt: skip
    early, late = float(out[0]), float(out[1])
    disk = sum(f.stat().st_size for f in path.iterdir()) / 1e6
    return {"windows": n, "store_mb": disk, "peak_rss_mb_at_10pct": early, "peak_rss_mb_at_end": late,
            "growth_ratio": late / early}  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--max-windows", type=int, default=1_000_000)
    ap.add_argument("--rss-windows", type=int, default=3000)
    args = ap.parse_args()
    sizes = [s for s in (1_000, 100_000, 1_000_000) if s <= args.max_windows]
    OUT.mkdir(exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="cclogfs-bench-", dir=OUT))
    try:
        print(f"machine: {machine()}")
        print("put throughput, 200-message windows of real /odom JSON, median of 5 runs:")
        put = bench_put(work)
        for label, r in put.items():
            print(f"  {label:<30} {r['windows_per_s']:8.0f} windows/s  {r['json_mb_per_s']:7.1f} MB/s of JSON"
                  f"  ({r['vs_fsync_per_put']:.1f}x fsync-per-put)")
        print("query latency for one second of data (100 windows of 1 message) and open time after a crash:")
        growth = bench_growth(work, sizes)
        first, last = growth[0], growth[-1]
        print(f"  query latency {last['windows']} vs {first['windows']} windows: "
              f"{last['query_ms_median'] / first['query_ms_median']:.2f}x; open after crash: "
              f"{last['open_after_crash_ms_median'] / first['open_after_crash_ms_median']:.2f}x")
        rss = bench_rss(work, args.rss_windows)
        print(f"peak RSS ingesting {rss['windows']} windows ({rss['store_mb']:.0f} MB stored): "
              f"{rss['peak_rss_mb_at_10pct']:.0f} MiB after 10 %, {rss['peak_rss_mb_at_end']:.0f} MiB at the end "
              f"({rss['growth_ratio']:.2f}x)")
        path = save_json("bench-store.json", {"machine": machine(), "put": put, "growth": growth, "rss": rss})
        print(f"saved {path}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0
