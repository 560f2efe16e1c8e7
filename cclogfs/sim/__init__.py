"""A fast, deterministic simulator of a BWIBot-like robot's odometry, with labelled anomalies.

    from cclogfs.sim import simulate
    run = simulate(seed=1, duration_s=600, rate_hz=100, anomalies=8, severity=(0.5, 1.5))
    run.messages          # [(stamp_ns, rosbridge JSON text)] of /odom
    run.stamp_ns, run.vx  # numpy arrays, one entry per /odom message (also x, y, yaw, wz, ...)
    run.events            # [Event(kind, start_ns, end_ns, severity, ...)], ground truth
    run.labels            # per message: 0 nominal, else 1 + KINDS.index(kind)
    run.write("out")      # out/run (rosbag2, MCAP, CDR), out/labels.json, out/run.jsonl

How it works and how its statistics compare with a real robot: docs/SIMULATOR.md.
"""

from .anomalies import KIND_GROUPS, KINDS, Event
from .run import DEFAULT_START_NS, SimRun, simulate

__all__ = ["DEFAULT_START_NS", "KINDS", "KIND_GROUPS", "Event", "SimRun", "simulate"]
