"""`cclog export`: a store's windows to MCAP or to Hive-partitioned Parquet."""

from __future__ import annotations

import argparse
import itertools
import os
import sys

from .common import Progress, Skipped, add_selection, nothing_matched, selected_windows
from .outputs import add_force, check_output

EXAMPLES = """\
examples:
  cclog export robot.store --mcap anomalies.mcap       # open in Foxglove or `mcap cat`
  cclog export robot.store --parquet lake/ --robot tb3-01
  cclog export robot.store --parquet lake/ --topic /odom --start 2015-05-21
  duckdb -c "SELECT robot, count(*), avg(\\"twist.twist.linear.x\\")
             FROM read_parquet('lake/**/*.parquet', hive_partitioning=true) GROUP BY robot"

Whole windows are exported: --start/--end choose the windows that overlap the range.
Parquet goes to DIR/robot=NAME/stream=STREAM/date=YYYY-MM-DD/part-*.parquet.
"""


HELP = "export stored windows to MCAP or Parquet"
DESCRIPTION = "Export the windows of a store to an MCAP file or a Parquet data set."


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_selection(p)
    to = p.add_mutually_exclusive_group(required=True)
    to.add_argument("--mcap", metavar="OUT.mcap", help="write one MCAP file (JSON channels)")
    to.add_argument("--parquet", metavar="DIR", help="write Hive-partitioned Parquet under DIR")
    p.add_argument("--robot", help="robot name for the Parquet partition (default: store name)")
    add_force(p, "--replace")  # --replace: the Parquet export's earlier spelling


def run(args: argparse.Namespace) -> int:
    # Before any work (and any temporary file). A Parquet directory may exist: the robot's
    # own partition is what --force replaces, checked by export_parquet.
    if args.mcap:
        check_output(args.mcap, [args.store], force=args.force)
    else:
        check_output(args.parquet, [args.store], force=True, directory=True)
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..export import export_mcap, export_parquet
    from ..store import open_store

    with open_store(args.store, readonly=True) as store, Progress("export") as progress:
        skipped = Skipped(store, args)
        windows = selected_windows(store, args, skipped)
        first = next(windows, None)
        if first is None and not (skipped.stretches or skipped.windows):
            raise nothing_matched(store, args)
        windows = itertools.chain([first] if first is not None else [], windows)
        if args.mcap:
            stats = export_mcap(windows, args.mcap, progress=progress)
        else:
            robot = args.robot or os.path.basename(os.path.normpath(args.store))
            stats = export_parquet(
                windows, args.parquet, robot=robot, replace=args.force, progress=progress
            )
    print(
        f"exported {stats.windows} windows, {stats.messages} messages of "
        f"{len(stats.streams)} streams to {len(stats.files)} files",
        file=sys.stderr,
    )
    return skipped.report()
