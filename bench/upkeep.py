"""Put latency while the recorder keeps its store to a budget and ages old windows.

    python -m bench upkeep [--puts 200000]

A `pipeline.Logger` gets synthetic 20 Hz /odom messages (windows of 100) as fast as it
takes them, three ways in the same run: no upkeep (the baseline), a 2 MiB budget
(retention in line), and the budget plus aging every float to 1e-3 after 600 s (a
background thread). Reported per way: median, p99, p99.99 and worst time of one put, and
what upkeep did.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import tempfile
import time
from pathlib import Path

from cclogfs.pipeline import Logger
from cclogfs.upkeep import Policy, Upkeep, parse_rule

from ._util import machine, save_json

NS = 1_000_000_000


def odom(i: int) -> str:
    t = i * 0.05
    return json.dumps({"header": {"stamp": {"sec": i // 20, "nanosec": i % 20 * 50_000_000}, "frame_id": "odom"},
                       "pose": {"x": math.sin(t) * 3.123456789, "y": t * 0.7071067811865476},
                       "twist": {"v": 0.25 + 0.01 * math.cos(t), "w": math.sin(t / 7)}})  # fmt: skip


def run(path: Path, puts: int, upkeep: Upkeep | None) -> dict:
    texts = [odom(i) for i in range(4000)]
    lat = []
    with Logger(str(path), chunk=100, upkeep=upkeep) as log:
        for i in range(puts):
            t = time.perf_counter()
            log("/odom", i * NS // 20, texts[i % len(texts)])
            lat.append(time.perf_counter() - t)
    lat.sort()
    pick = lambda q: lat[min(len(lat) - 1, int(len(lat) * q))]  # noqa: E731
    return {"median_us": 1e6 * pick(0.5), "p99_us": 1e6 * pick(0.99), "p9999_ms": 1e3 * pick(0.9999),
            "worst_ms": 1e3 * lat[-1], "aged_windows": getattr(upkeep, "aged_windows", 0),
            "dropped_segments": getattr(upkeep, "dropped_segments", 0),
            "errors": list(getattr(upkeep, "errors", []))}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--puts", type=int, default=200_000)
    args = ap.parse_args()
    print(machine())
    ways = {
        "none": lambda: None,
        "budget 2 MiB": lambda: Upkeep(budget=2 << 20),
        "budget + aging": lambda: Upkeep(budget=2 << 20, policy=Policy([parse_rule("1e-3")]), older_than_ns=600 * NS),
    }
    tmp = Path(tempfile.mkdtemp(prefix="cclog-upkeep-"))
    rows = {}
    try:
        print(f"{'upkeep':16} {'median us':>9} {'p99 us':>7} {'p99.99 ms':>9} {'worst ms':>8}  what it did")
        for name, make in ways.items():
            shutil.rmtree(tmp / "s", ignore_errors=True)
            r = rows[name] = run(tmp / "s", args.puts, make())
            print(f"{name:16} {r['median_us']:9.1f} {r['p99_us']:7.0f} {r['p9999_ms']:9.1f} {r['worst_ms']:8.1f}  "
                  f"{r['dropped_segments']} segments dropped, {r['aged_windows']} windows aged"
                  + (f", errors: {r['errors']}" if r["errors"] else ""))  # fmt: skip
        base = rows["none"]["p99_us"]
        print("p99 against no upkeep: " + ", ".join(f"{k} {v['p99_us'] / base:.2f}x" for k, v in rows.items()))
        save_json("bench-upkeep.json", {"machine": machine(), "puts": args.puts, "ways": rows})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
