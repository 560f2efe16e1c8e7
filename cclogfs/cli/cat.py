"""`cclog cat`: a store's messages as JSON Lines on standard output."""

from __future__ import annotations

import argparse
import sys

from .common import Progress, Skipped, add_selection, nothing_matched, selected_windows

EXAMPLES = """\
examples:
  cclog cat robot.store                              # everything, in time order
  cclog cat robot.store --topic /odom --start 928.5 --end 930s
  cclog cat robot.store --start 2015-05-21T19:14:55Z | jq .msg.pose.pose.position

Times: nanoseconds (1432235695834049087ns), seconds (1432235695.83 or 12s), ISO-8601
(UTC when no zone is given), or a bare integer: seconds below 1e11, else nanoseconds.
A selection that matches no message is an error (exit 1) naming what the store holds. Each msg is printed exactly as it was stored; messages of
several streams are merged by stamp. Windows that `cclog compact` aged hold values within
their stated error bounds; a note on stderr says how many were printed.
"""


DESCRIPTION = "Print the messages of a store as JSON Lines, in time order."


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_selection(p)


def run(args: argparse.Namespace) -> int:
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..export.jsonl import write_jsonl
    from ..store import open_store

    aged = [0, 0]  # windows aged, windows in all

    def counted(windows):
        for w in windows:
            aged[1] += 1
            aged[0] += w.aged is not None
            yield w

    with open_store(args.store, readonly=True) as store, Progress("cat") as progress:
        skipped = Skipped(store, args)
        n = write_jsonl(
            counted(selected_windows(store, args, skipped)),
            sys.stdout,
            start_ns=args.start,
            end_ns=args.end,
            progress=progress,
        )
        sys.stdout.flush()
        if n == 0 and not (skipped.stretches or skipped.windows):
            raise nothing_matched(store, args)
    if aged[0]:
        print(f"cclog: note: {aged[0]} of {aged[1]} windows were aged by compaction: their values are "
              "within stated error bounds, not byte-exact (`cclog info` says how)", file=sys.stderr)  # fmt: skip
    return skipped.report()
