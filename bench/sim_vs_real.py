#!/usr/bin/env python3
"""Nominal simulated odometry against the real TurtleBot run's /odom: percentiles and a PNG.

    python bench/sim_vs_real.py [--bag ../shared/data/nav2_turtlebot.mcap]
                                [--duration 3600] [--seeds 3] [--png docs/sim_vs_real.png]

Speed is twist.linear.x, yaw rate twist.angular.z, acceleration the difference of
consecutive speeds over the difference of their header stamps. The simulator runs
nominal (no anomalies) at the real run's rate, and at 100 Hz for the last table rows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cclogfs.jsontext.ros import message_stamp_ns  # noqa: E402
from cclogfs.sim import simulate  # noqa: E402

PCTS = (1, 5, 25, 50, 75, 95, 99)


def read_real(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Header stamps (ns), vx and wz of /odom."""
    from rosbags.highlevel import AnyReader

    st, vx, wz = [], [], []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == "/odom"]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            st.append(message_stamp_ns(msg))
            vx.append(msg.twist.twist.linear.x)
            wz.append(msg.twist.twist.angular.z)
    return np.array(st, np.int64), np.array(vx), np.array(wz)


def stats(stamp_ns: np.ndarray, vx: np.ndarray, wz: np.ndarray) -> dict[str, np.ndarray]:
    dt = np.diff(stamp_ns) / 1e9
    return {"speed": vx, "accel": np.diff(vx) / dt, "yaw_rate": wz}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bag", type=Path, default=ROOT.parent / "shared" / "data" / "nav2_turtlebot.mcap")
    ap.add_argument("--duration", type=float, default=3600.0)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--png", type=Path, default=ROOT / "docs" / "sim_vs_real.png")
    args = ap.parse_args()

    st, vx, wz = read_real(args.bag)
    real = stats(st, vx, wz)
    rate = 1e9 / float(np.median(np.diff(st)))
    sims: dict[str, dict[str, np.ndarray]] = {}
    for hz in (rate, 100.0):
        parts = [simulate(seed=s, duration_s=args.duration, rate_hz=hz) for s in range(args.seeds)]
        per = [stats(p.stamp_ns, p.vx, p.wz) for p in parts]
        sims[f"sim {hz:.1f} Hz"] = {k: np.concatenate([d[k] for d in per]) for k in per[0]}
    rows = {f"real {rate:.1f} Hz": real, **sims}

    print(f"real: {args.bag.name} /odom, {len(vx)} msgs, {(st[-1] - st[0]) / 1e9:.1f} s at {rate:.1f} Hz")
    print(f"sim: nominal, {args.seeds} seeds x {args.duration:g} s")
    print(f"{'quantity':<9} {'source':<14} {'stopped':>7} " + " ".join(f"{'p' + str(p):>7}" for p in PCTS))
    for q in ("speed", "accel", "yaw_rate"):
        for name, d in rows.items():
            x = d[q]
            pct = np.percentile(x, PCTS)
            stopped = np.mean(np.abs(x) < 1e-3) * 100
            print(f"{q:<9} {name:<14} {stopped:6.1f}% " + " ".join(f"{v:7.3f}" for v in pct))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bins = {"speed": np.linspace(-0.3, 1.2, 61), "accel": np.linspace(-1.5, 1.5, 61),
            "yaw_rate": np.linspace(-1.5, 1.5, 61)}
    units = {"speed": "m/s", "accel": "m/s²", "yaw_rate": "rad/s"}
    fig, axes = plt.subplots(len(rows), 3, figsize=(13, 3.0 * len(rows)), sharex="col")
    for r, (name, d) in enumerate(rows.items()):
        for c, q in enumerate(("speed", "accel", "yaw_rate")):
            ax = axes[r, c]
            x = np.clip(d[q], bins[q][0], bins[q][-1])
            ax.hist(x, bins=bins[q], density=True, color="C0" if r == 0 else "C1")
            ax.set_yscale("log")
            ax.set_title(f"{name}: {q.replace('_', ' ')}", fontsize=10)
            if r == len(rows) - 1:
                ax.set_xlabel(f"{q.replace('_', ' ')} ({units[q]}), clipped to the axis")
    fig.suptitle("Nominal /odom: real TurtleBot (nav2 run) vs simulator (density, log scale)")
    fig.tight_layout()
    args.png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.png, dpi=80)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
