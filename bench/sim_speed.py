#!/usr/bin/env python3
"""How fast the simulator makes an hour of odometry (target: 100 Hz for 3600 s in < 30 s).

    python bench/sim_speed.py [--duration 3600] [--rate 100] [--repeat 3]

Prints the median of --repeat runs for each stage: simulate() (arrays and labels),
the /odom JSON texts, and writing bag + labels + JSONL; and, as the baseline measured
in the same run, the JSON made the plain way (rosbags objects through message_to_json)
on a tenth of the messages, scaled up.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from cclogfs.jsontext.ros import message_to_json  # noqa: E402
from cclogfs.sim import simulate  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    times: dict[str, list[float]] = {"simulate": [], "json": [], "write": [], "baseline_json": []}
    n = 0
    for rep in range(args.repeat):
        t0 = time.perf_counter()
        run = simulate(seed=rep, duration_s=args.duration, rate_hz=args.rate, anomalies=20)
        t1 = time.perf_counter()
        msgs = run.messages
        t2 = time.perf_counter()
        tmp = Path(tempfile.mkdtemp(prefix="sim_speed_"))
        try:
            run.write(tmp / "out")
        finally:
            t3 = time.perf_counter()
            shutil.rmtree(tmp)
        objs = run.ros_messages("/odom")[: len(msgs) // 10]
        t4 = time.perf_counter()
        plain = [message_to_json(m) for m in objs]
        t5 = time.perf_counter()
        assert plain == [text for _, text in msgs[: len(plain)]]
        n = len(msgs)
        times["simulate"].append(t1 - t0)
        times["json"].append(t2 - t1)
        times["write"].append(t3 - t2)
        times["baseline_json"].append((t5 - t4) * n / max(1, len(objs)))
    med = {k: statistics.median(v) for k, v in times.items()}
    print(f"{n} /odom messages ({args.duration:g} s at {args.rate:g} Hz), median of {args.repeat} runs")
    print(f"  simulate() arrays+labels   {med['simulate']:7.2f} s")
    print(f"  /odom JSON texts           {med['json']:7.2f} s")
    print(f"  simulate + JSON            {med['simulate'] + med['json']:7.2f} s   (target < 30 s)")
    print(f"  write bag+labels+JSONL     {med['write']:7.2f} s")
    print(f"  baseline JSON (message_to_json, scaled from {n // 10} msgs) {med['baseline_json']:7.2f} s"
          f"  -> template is {med['baseline_json'] / med['json']:.1f}x faster")
    return 0


if __name__ == "__main__":
    sys.exit(main())
