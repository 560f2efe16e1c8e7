"""`cclog simulate`: write a simulated run (rosbag2/MCAP, labels, JSONL) with anomalies."""

from __future__ import annotations

import argparse
import time

from ..errors import InvalidInputError
from .outputs import refuse_store_dir

EXAMPLES = """\
examples:
  cclog simulate --seed 1 --duration 600 --anomalies 8 --out runs/s1
  cclog simulate --seed 2 --duration 3600 --nominal --out runs/nominal    # no anomalies
  cclog simulate --seed 3 --rate 30 --severity 0.3:0.8 --kinds collision,wheel_slip --out runs/mild
  cclog simulate --seed 4 --duration 1800 --rate-per-min 0.5 --imu --tf --out runs/s4
  cclog simulate --seed 5 --robot-seed 1 --heading imu --out runs/s5  # robot 1, gyro yaw

writes OUT/run (a rosbag2 directory, MCAP storage, /odom as nav_msgs/msg/Odometry),
OUT/labels.json ({"events": [{"start_ns", "end_ns", "kind", "group", "severity"}]})
and OUT/run.jsonl (one {"topic", "stamp_ns", "msg"} object per line).
"""


def _severity(text: str) -> tuple[float, float]:
    lo, sep, hi = text.partition(":")
    try:
        pair = (float(lo), float(hi if sep else lo))
    except ValueError:
        msg = f"expected LOW:HIGH such as 0.5:1.5, got {text!r}"
        raise argparse.ArgumentTypeError(msg) from None
    return pair


DESCRIPTION = "Simulate a BWIBot-like robot driving a building, with injected, labelled anomalies."


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..sim import KINDS

    p.description += f" Kinds: {', '.join(KINDS)}."
    p.add_argument("--out", required=True, help="output directory (created; must not hold a run)")
    p.add_argument("--seed", type=int, default=0,
                   help="random seed (default 0); same seed, same bytes")
    p.add_argument("--duration", type=float, default=600.0, help="seconds (default 600)")
    p.add_argument("--rate", type=float, default=100.0, help="odometry rate in Hz (default 100)")
    p.add_argument("--anomalies", type=int, help="number of anomalies (default 8)")
    p.add_argument("--rate-per-min", type=float, default=None,
                   help="instead of --anomalies: a Poisson count at this many per minute")
    p.add_argument("--nominal", action="store_true", help="no anomalies at all")
    p.add_argument("--severity", type=_severity, default=(0.5, 1.5),
                   help="LOW:HIGH severity range, 1.0 = default strength (default 0.5:1.5)")
    p.add_argument("--kinds", default=None, help="comma-separated anomaly kinds (default: all)")
    p.add_argument("--robot-seed", type=int, default=None,
                   help="fix the robot (acceleration limit, odometry calibration) across seeds")
    p.add_argument("--heading", choices=["wheels", "imu"], default="wheels",
                   help="odometry yaw from the wheels (default) or the IMU (slip then shows)")
    p.add_argument("--imu", action="store_true", help="also write /imu (sensor_msgs/msg/Imu)")
    p.add_argument("--tf", action="store_true", help="also write /tf (odom -> base_link)")


def run(args: argparse.Namespace) -> int:
    from ..sim import simulate

    if args.nominal and args.rate_per_min is not None:
        raise InvalidInputError("--nominal and --rate-per-min contradict each other; give one.")
    if args.anomalies is not None and (args.nominal or args.rate_per_min is not None):
        # Either would silently win over the count asked for.
        other = "--nominal" if args.nominal else "--rate-per-min"
        raise InvalidInputError(f"--anomalies and {other} contradict each other; give one.")
    refuse_store_dir(args.out)
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()] if args.kinds else None
    t0 = time.perf_counter()
    sim = simulate(
        seed=args.seed,
        duration_s=args.duration,
        rate_hz=args.rate,
        anomalies=0 if args.nominal else 8 if args.anomalies is None else args.anomalies,
        anomaly_rate_per_min=None if args.nominal else args.rate_per_min,
        kinds=kinds,
        severity=args.severity,
        robot_seed=args.robot_seed,
        heading=args.heading,
    )
    paths = sim.write(args.out, imu=args.imu, tf=args.tf)
    print(sim.summary())
    for name, path in paths.items():
        print(f"{name}: {path}")
    print(f"done in {time.perf_counter() - t0:.1f} s")
    return 0
