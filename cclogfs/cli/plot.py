"""`cclog plot STORE`: PNG plots of a store's trajectory, speed, windows and anomaly scores."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from ..errors import InvalidInputError

EXAMPLES = """\
examples:
  cclog plot robot.store                         # plots/trajectory.png, speed.png, windows.png
  cclog plot robot.store --topic /amcl_pose --out figs

The trajectory is the first stream of type nav_msgs/Odometry, PoseStamped or
PoseWithCovarianceStamped (else /odom), or --topic. Speed is the twist when the messages
have one, else from consecutive poses. Smart-logged stores also show each window's peak
anomaly score and, from /cclog/summary, the anomalous messages per summary period. A store
without poses gets windows.png only.
"""

DESCRIPTION = "Plot a store: the trajectory, speed and stored windows over time, and anomaly scores."


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("store", help="store directory")
    p.add_argument("--topic", metavar="T", help="the pose stream to draw (default: found by message type)")
    p.add_argument("--out", default="plots", help="directory for the PNG files (default %(default)s)")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.exists() and not out.is_dir():  # before the store is read: fail fast, write nothing
        raise InvalidInputError(f"--out {out} is a file, not a directory for the PNG files")
    if Path(os.path.realpath(out)).is_relative_to(os.path.realpath(args.store)):
        # PNGs in the store would be files it does not hold (`cclog fsck` warns of each).
        raise InvalidInputError(f"--out {out} is the store {args.store} (or inside it); the store is never "
                                "written: choose another directory for the PNG files")  # fmt: skip

    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..plot.store import plot_data, plot_store
    from ..runs import hidden_by_default
    from ..store import open_store
    from .common import refuse_cut_tail

    with open_store(args.store, readonly=True) as store:
        refuse_cut_tail(store, skip=None)  # no --skip-damaged here: refused outright
        if all(hidden_by_default(n) for n in store.streams()):  # else an empty windows.png and exit 0
            raise InvalidInputError(f"{args.store} holds no messages: nothing to plot")
        data = plot_data(store, args.topic)
    paths = plot_store(data, out)
    if not len(data.x):
        print(f"cclog: no pose stream in {args.store} (name one with --topic): windows only", file=sys.stderr)
    if data.undrawn:
        print(f"cclog: note: {data.undrawn:,} of {len(data.x):,} messages of {data.topic} left out of the "
              "trajectory or speed plot: a position or speed is NaN, infinite or beyond 1e100",
              file=sys.stderr)  # fmt: skip
    for path in paths:
        print(path)
    return 0
