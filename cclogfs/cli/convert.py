"""`cclog convert`: any log source (bag, MCAP, JSONL) to JSON Lines."""

from __future__ import annotations

import argparse
import sys

from .common import Progress, check_topics_exist, damaged_exit, no_source_message
from .outputs import add_force, atomic_output, check_output

EXAMPLES = """\
examples:
  cclog convert run.mcap -o run.jsonl                 # every topic of a ROS 2 bag
  cclog convert run.bag -o odom.jsonl --topic /odom   # one topic of a ROS 1 bag
  cclog convert rosbag2_dir/ -o - | head              # a ROS 2 bag directory, to stdout
  cat raw.jsonl | cclog convert - -o clean.jsonl --on-error skip

A damaged ROS 1 bag, MCAP file or ROS 2 .db3 (cut short, index lost) is read as far as it can
be: every readable message is written, stderr says what was lost, and the exit code is 4. A
ROS 2 bag directory without metadata.yaml is read from its .db3 files (a note on stderr).

Each line is {"topic": ..., "stamp_ns": ..., "msg": {...}}: msg is the message as
rosbridge JSON (docs/JSON.md), stamp_ns its log time (--clock header: its header.stamp,
else its log time).
"""


DESCRIPTION = "Read a ROS 1/ROS 2 bag, an MCAP file or JSON Lines and write JSON Lines."


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", help="bag file, ROS 2 bag directory, .mcap, .jsonl, or - (stdin)")
    p.add_argument("-o", "--output", required=True, help="output .jsonl file, or - for stdout")
    p.add_argument("--topic", action="append", metavar="T", help="keep only topic T (repeatable)")
    p.add_argument("--clock", choices=["log", "header"], default="log",
                   help="stamp_ns of a bag's message: its log (receive) time (default) or header.stamp (docs/JSON.md)")
    add_force(p)
    p.add_argument(
        "--on-error",
        choices=("stop", "skip"),
        default="stop",
        help="a malformed JSONL input line stops the run (default) or is skipped with a warning",
    )


def run(args: argparse.Namespace) -> int:
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..ingest import open_source

    def warn(err: Exception) -> None:
        print(f"cclog convert: skipped: {err}", file=sys.stderr)

    if args.output != "-":
        check_output(args.output, [args.source], force=args.force)
    with open_source(args.source, args.topic, on_error=args.on_error, report=warn, clock=args.clock) as src:
        check_topics_exist(src, args.source, args.topic)
        if args.output == "-":
            _write(src, sys.stdout, args)
        else:
            with atomic_output(args.output) as out:
                _write(src, out, args)
    if skipped := getattr(src, "skipped", 0):  # a salvaging reader skips nothing
        unit = getattr(src, "bad_unit", "messages")
        print(f"cclog convert: SKIPPED {skipped:,} bad {unit} (named above), not written (exit 4)", file=sys.stderr)
    return damaged_exit(src)


def _write(src, out, args: argparse.Namespace) -> None:
    from ..jsontext.lines import format_line

    seen: set[str] = set()
    with Progress("convert") as progress:
        for m in src:
            out.write(format_line(m.topic, m.stamp_ns, m.text))
            seen.add(m.topic)
            progress()
    if progress.count == 0:  # raised inside the output's block: no empty output is left
        raise no_source_message(args.source, args.topic, src)
    # A JSONL source learns its topics by reading (a bag's missing --topic is refused before).
    if missing := [t for t in dict.fromkeys(args.topic or ()) if t not in seen]:
        raise no_source_message(args.source, missing, src)
