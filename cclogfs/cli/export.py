"""`cclog export`: a store's windows to MCAP, to a rosbag2 bag or to Hive-partitioned Parquet."""

from __future__ import annotations

import argparse
import itertools
import os
import sys

from ..errors import InvalidInputError
from .common import Progress, Skipped, add_selection, nothing_matched, selected_windows, why_records
from .outputs import add_force, check_output

EXAMPLES = """\
examples:
  cclog export robot.store --mcap anomalies.mcap       # ROS 2 MCAP: ros2 bag play, Foxglove, rosbags
  cclog export robot.store --mcap anomalies.mcap --encoding json   # every stream as JSON text
  cclog export robot.store --rosbag2 anomalies_bag/    # a rosbag2 directory: ros2 bag play anomalies_bag
  cclog export robot.store --parquet lake/ --robot tb3-01
  cclog export robot.store --parquet lake/ --topic /odom --start 2015-05-21
  duckdb -c "SELECT robot, count(*), avg(\\"twist.twist.linear.x\\")
             FROM read_parquet('lake/**/*.parquet', hive_partitioning=true) GROUP BY robot"

--start/--end export the messages in the range, both ends included, as `cclog cat` prints
them: a window reaching past an end is cut to it (its MCAP window metadata gives the cut span).
MCAP: a stream whose ROS type rosbags knows (ROS 2 types; a ROS 1 type by its ROS 2 name)
is written as `ros2 bag record` writes it (CDR, ros2msg schema); any other stream as JSON,
said on stderr. ROS 1 shapes are mapped and counted on stderr (header.seq left out,
CameraInfo.D taken as d, a field ROS 2 added written as zero); any other value that does
not fit the type stops the export with an error naming the stream, message and field.
Parquet goes to DIR/robot=NAME/stream=STREAM/date=YYYY-MM-DD/part-*.parquet.
"""


DESCRIPTION = "Export the windows of a store to an MCAP file, a rosbag2 bag or a Parquet data set."


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_selection(p)
    to = p.add_mutually_exclusive_group(required=True)
    to.add_argument("--mcap", metavar="OUT.mcap", help="write one MCAP file (ROS 2 CDR where the type is known, else JSON)")
    to.add_argument("--rosbag2", metavar="DIR", help="write a rosbag2 bag (metadata.yaml + MCAP, ROS 2 CDR) "
                    "that ros2 bag play and rosbags open; every stream must have a ROS 2 type")  # fmt: skip
    to.add_argument("--parquet", metavar="DIR", help="write Hive-partitioned Parquet under DIR")
    p.add_argument("--robot", help="robot name for the Parquet partition (default: store name)")
    p.add_argument("--encoding", choices=("auto", "cdr", "json"),
                   help="MCAP message encoding: auto (CDR where the ROS type is known, JSON for the rest; "
                        "default), cdr (refuse a stream that cannot be CDR), json (every stream as JSON)")  # fmt: skip
    add_force(p, "--replace")  # --replace: the Parquet export's earlier spelling


def run(args: argparse.Namespace) -> int:
    # Before any work (and any temporary file). A Parquet directory may exist: the robot's
    # own partition is what --force replaces, checked by export_parquet.
    if args.encoding and not args.mcap:
        raise InvalidInputError("--encoding is for --mcap (a rosbag2 bag is all CDR; Parquet columns are typed "
                                "from the JSON).")  # fmt: skip
    if "-" in (args.mcap, args.rosbag2, args.parquet):  # `convert -o -` is stdout; this made a file named "-"
        raise InvalidInputError("export writes files, not standard output: give a file or directory name, not -")
    if args.mcap:
        check_output(args.mcap, [args.store], force=args.force)
    elif args.rosbag2:
        from ..export.rosbag2 import check_rosbag2_output

        check_output(args.rosbag2, [args.store], force=args.force, directory=True)
        check_rosbag2_output(args.rosbag2, force=args.force)
    else:
        check_output(args.parquet, [args.store], force=True, directory=True)
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..export import Clip, export_mcap, export_parquet, export_rosbag2
    from ..store import open_store

    with open_store(args.store, readonly=True) as store, Progress("export") as progress:
        skipped = Skipped(store, args)
        clip = Clip(args.start, args.end)
        windows = clip(selected_windows(store, args, skipped))
        first = next(windows, None)
        if first is None and not (skipped.stretches or skipped.windows):
            raise nothing_matched(store, args)
        windows = itertools.chain([first] if first is not None else [], windows)
        if args.mcap:
            stats = export_mcap(windows, args.mcap, encoding=args.encoding or "auto", progress=progress,
                                describe=_describer(store))
        elif args.rosbag2:
            stats = export_rosbag2(windows, args.rosbag2, replace=args.force, progress=progress,
                                   describe=_describer(store))
        else:
            robot = args.robot or os.path.basename(os.path.normpath(args.store))
            stats = export_parquet(
                windows, args.parquet, robot=robot, replace=args.force, progress=progress
            )
    notes = []
    if stats.records != stats.windows:  # as `cclog info` says it
        notes.append(f"stored as {stats.records} records: {why_records(stats.counted.joined)}")
    if clip.left_out:
        cut = f"{clip.cut} records" if stats.records != stats.windows else clip.cut
        notes.append(f"{cut} cut to --start/--end: {clip.left_out:,} messages outside left out")
    said = f" ({'; '.join(notes)})" if notes else ""
    if stats.summaries:  # the recorder's own, apart from the windows of messages kept, as `record` says them
        said += f" and {stats.summaries} summaries"
    print(f"exported {stats.windows} windows{said}, {stats.messages} messages of {len(stats.streams)} streams to "
          f"{len(stats.files)} files", file=sys.stderr)  # fmt: skip
    if args.mcap or args.rosbag2:
        _report_mcap(stats)
    return skipped.report()


def _describer(store):
    """stream -> its type as the store knows it, with the definition and latching that only
    a recording's first window holds (the selected windows may start later)."""
    from ..play.pace import stream_types

    return lambda name: stream_types(store, [name]).get(name, {})


def _report_mcap(stats) -> None:
    """What the MCAP could not carry as the store has it: never silent."""
    for stream, why in sorted(stats.json_streams.items()):
        print(f"note: {stream} exported as JSON, not CDR: {why}; rosbags and ros2 bag refuse a file with "
              "JSON channels: leave the stream out with --topic, or export all as JSON with --encoding json",
              file=sys.stderr)  # fmt: skip
    for (stream, sentence), n in sorted(stats.notes.items()):
        print(f"note: {stream}: " + sentence.format(n=f"{n:,} message{'s' * (n != 1)}"), file=sys.stderr)
