"""Write a JSONL file of synthetic sensor_msgs/LaserScan messages (../shared/data has none).

    python bench/laser_scans.py -o scans.jsonl [--count 600] [--intensities none|zeros]

A TurtleBot3-like 360-beam scanner (range 0.12-3.5 m, 5 Hz) driven on a loop through an
8 x 5 m room with three round obstacles: each beam is cast against the walls and the
obstacles, with 1 cm of noise, 2% dropouts, and beyond range as Infinity, the floats
rounded to float32 as the message holds them. Fields in the order of the message type,
as `cclog convert` writes rosbridge JSON; `"intensities": []` (a driver that sends none,
the default here) is the message's last key. Deterministic for a given --seed.
"""

from __future__ import annotations

import argparse
import json
import math
import random

import numpy as np

BEAMS = 360
RANGE_MIN, RANGE_MAX = 0.12, 3.5
ROOM = (8.0, 5.0)
OBSTACLES = [(2.0, 1.5, 0.3), (5.5, 3.5, 0.4), (6.5, 1.2, 0.25)]  # x, y, radius


def f32(x: float) -> float:
    return float(np.float32(x))


def cast(x: float, y: float, heading: float) -> np.ndarray:
    """The distance to the nearest wall or obstacle along each beam."""
    angles = heading + np.arange(BEAMS) * (2 * math.pi / BEAMS)
    dx, dy = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (ROOM[0] - x) / dx, np.where(dx < 0, -x / dx, np.inf))
        ty = np.where(dy > 0, (ROOM[1] - y) / dy, np.where(dy < 0, -y / dy, np.inf))
    best = np.minimum(tx, ty)
    for ox, oy, r in OBSTACLES:
        # |p + t d - o| = r: t^2 - 2 t (d . (o - p)) + |o - p|^2 - r^2 = 0
        b = dx * (ox - x) + dy * (oy - y)
        c = (ox - x) ** 2 + (oy - y) ** 2 - r * r
        disc = b * b - c
        t = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)
        best = np.minimum(best, np.where(t > 0, t, np.inf))
    return best


def scan(i: int, rng: random.Random, zeros: bool) -> dict:
    t = i * 0.2
    x, y = 4.0 + 2.5 * math.cos(t / 20), 2.5 + 1.5 * math.sin(t / 20)
    heading = t / 20 + math.pi / 2
    ranges = []
    for d in cast(x, y, heading):
        d += rng.gauss(0, 0.01)
        ranges.append(math.inf if d > RANGE_MAX or rng.random() < 0.02 else f32(max(d, RANGE_MIN)))
    stamp_ns = 1_700_000_000_000_000_000 + i * 200_000_000 + rng.randrange(0, 3_000_000)
    return {
        "header": {
            "stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9},
            "frame_id": "base_scan",
        },
        "angle_min": 0.0,
        "angle_max": f32(2 * math.pi),
        "angle_increment": f32(2 * math.pi / BEAMS),
        "time_increment": 0.0,
        "scan_time": 0.0,
        "range_min": f32(RANGE_MIN),
        "range_max": RANGE_MAX,
        "ranges": ranges,
        "intensities": [0.0] * BEAMS if zeros else [],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", required=True)
    parser.add_argument("--count", type=int, default=600)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--intensities", choices=["none", "zeros"], default="none")
    args = parser.parse_args()
    rng = random.Random(args.seed)
    with open(args.out, "w") as out:
        for i in range(args.count):
            msg = scan(i, rng, args.intensities == "zeros")
            stamp_ns = msg["header"]["stamp"]["sec"] * 10**9 + msg["header"]["stamp"]["nanosec"]
            out.write(json.dumps({"topic": "/scan", "stamp_ns": stamp_ns, "msg": msg}) + "\n")


if __name__ == "__main__":
    main()
