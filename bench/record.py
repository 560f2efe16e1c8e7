"""`cclog record` end to end: messages/s from a bag and from JSONL on stdin, every message
kept or smart logging, and peak memory as the input grows.

    python -m bench record [--minutes 10] [--runs 3]

Input: a simulated run at 100 Hz (/odom and /imu), as a ROS 2 bag (MCAP) and as JSONL.
Each figure is the median of --runs child processes running the real CLI (the timer starts
after the interpreter and cclogfs are loaded); the baseline, measured in the same run, is
a bare `json.loads` of every JSONL line. Targets (issue 6): >= 20,000 msg/s from a bag,
>= 100,000 msg/s from JSONL keeping everything, >= 50,000 msg/s smart logging from JSONL;
memory must not grow with the input.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ._util import OUT, machine, save_json

ROOT = Path(__file__).resolve().parent.parent

CHILD = """
import sys, time
from bench._util import peak_rss_mib
from cclogfs.cli import main
argv = sys.argv[1:]
t = time.perf_counter()
code = main(argv)
print(time.perf_counter() - t, peak_rss_mib(), code)
"""


def run_cli(args: list[str], stdin: Path | None = None) -> tuple[float, float]:
    """(seconds, peak RSS MiB) of one `cclog ARGS` in a fresh process."""
    with open(stdin, "rb") if stdin else open("/dev/null", "rb") as f:
        out = subprocess.run([sys.executable, "-c", CHILD, *args], stdin=f, capture_output=True,
                             text=True, cwd=ROOT, check=True)  # fmt: skip
    secs, rss_mib, code = out.stdout.split()
    if code != "0":
        raise RuntimeError(f"cclog {' '.join(args)} exited {code}: {out.stderr}")
    return float(secs), float(rss_mib)


def median_run(make_args, runs: int, stdin: Path | None = None) -> tuple[float, float]:
    results = [run_cli(make_args(i), stdin) for i in range(runs)]
    return statistics.median(r[0] for r in results), max(r[1] for r in results)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from cclogfs.classifier import train
    from cclogfs.sim import simulate

    OUT.mkdir(exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="cclogfs-bench-record-", dir=OUT))
    try:
        run = simulate(seed=7, duration_s=args.minutes * 60, rate_hz=100, anomalies=int(args.minutes))
        paths = run.write(work / "run", imu=True)
        jsonl, bag = paths["jsonl"], paths["bag"]
        lines = jsonl.read_bytes().splitlines(keepends=True)
        n = len(lines)
        big = work / "x4.jsonl"  # the same run four times over, for the memory check
        big.write_bytes(b"".join(lines) * 4)
        model = work / "model"
        train([[t for _, t in simulate(seed=s, duration_s=90, rate_hz=100).messages] for s in (1, 2)]).save(model)

        t = time.perf_counter()
        for line in lines:
            json.loads(line)
        baseline = n / (time.perf_counter() - t)

        def store(i: int) -> str:
            path = work / f"store{i}-{time.monotonic_ns()}"
            return str(path)

        rows = []
        cases = [
            ("bag, every message (columnar)", lambda i: ["record", str(bag), "--store", store(i)], None, n, 20_000),
            ("bag, every message (zstd)", lambda i: ["record", str(bag), "--store", store(i), "--codec", "zstd"], None, n, 20_000),
            ("JSONL stdin, every message (columnar)", lambda i: ["record", "-", "--store", store(i)], jsonl, n, 100_000),
            ("JSONL stdin, every message (zstd)", lambda i: ["record", "-", "--store", store(i), "--codec", "zstd"], jsonl, n, 100_000),
            ("JSONL stdin, smart logging", lambda i: ["record", "-", "--store", store(i), "--model", str(model)], jsonl, n, 50_000),
            ("JSONL stdin x4, every message (zstd)", lambda i: ["record", "-", "--store", store(i), "--codec", "zstd"], big, 4 * n, 100_000),
        ]  # fmt: skip
        print(f"machine: {machine()}")
        print(f"input: {args.minutes:g} min simulated at 100 Hz, {n:,} messages (/odom, /imu), "
              f"{jsonl.stat().st_size / 1e6:.1f} MB of JSONL; baseline json.loads per line: {baseline:,.0f} msg/s")
        print(f"{'case':<40} {'msg/s':>9} {'target':>8} {'vs json.loads':>13} {'peak RSS':>9}")
        for label, make, stdin, count, target in cases:
            secs, rss = median_run(make, args.runs, stdin)
            rows.append({"case": label, "messages": count, "msg_per_s": count / secs, "target": target,
                         "vs_json_loads": count / secs / baseline, "peak_rss_mib": rss})  # fmt: skip
            r = rows[-1]
            print(f"{label:<40} {r['msg_per_s']:>9,.0f} {target:>8,} {r['vs_json_loads']:>12.2f}x {rss:>7.0f} MiB",
                  flush=True)  # fmt: skip
            for p in work.glob("store*"):
                shutil.rmtree(p)
        one, four = rows[3]["peak_rss_mib"], rows[5]["peak_rss_mib"]
        print(f"peak RSS, 4x the input vs 1x (zstd, every message): {four:.0f} vs {one:.0f} MiB ({four / one:.2f}x)")
        path = save_json("bench-record.json", {"machine": machine(), "baseline_json_loads": baseline, "rows": rows})
        print(f"saved {path}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0
