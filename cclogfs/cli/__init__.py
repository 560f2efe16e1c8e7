"""The `cclog` command line. Each subcommand is a module in this package that defines
DESCRIPTION, EXAMPLES, `add_arguments(parser)` and `run(args)`; the table below is the
only place that names them, with the line `cclog --help` shows for each.

Start-up time is part of every command (a one-second `cclog cat` is mostly start-up), so
a subcommand module imports only light modules at its top and its engine, sources or
classifier inside `run`; `main` gives arguments only to the subcommand being run."""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import CclogError

# One module per subcommand, in the order `cclog --help` lists them, with its help line:
# here, so that `cclog --help` imports none of them (it took 13 modules and, through their
# imports, dataclasses, inspect, secrets and datetime: most of its time; issue 14).
COMMANDS: dict[str, str] = {
    "demo": "train, smart-log and report on simulated runs",
    "record": "log a bag, MCAP file or JSONL stream into a store",
    "play": "publish a store's messages at their recorded pace (JSONL or ROS 1)",
    "plot": "PNG plots of a store: trajectory, speed, windows, anomaly scores",
    "cat": "print stored messages as JSON Lines",
    "info": "streams, windows, messages, time span and sizes of a store",
    "fsck": "verify every record, index and the manifest of a store",
    "compact": "age old windows to lower fidelity and fit a storage budget",
    "export": "export stored windows to MCAP, a rosbag2 bag or Parquet",
    "convert": "convert a bag, MCAP or JSONL file to JSON Lines",
    "simulate": "simulate a robot run with labelled anomalies",
    "train": "learn mode: fit an anomaly model on nominal odometry",
    "eval": "score a labelled run: Table 1, events recalled, bytes kept",
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole parser (`command` None), or with `command` that subcommand's parser alone:
    parsing `cclog cat ...` needs no other, and importing every subcommand module was a
    quarter of a one-second `cat` (issue 14). With "" every subcommand is listed with its
    help line and nothing more (no options, no `func`), which is all `cclog --help` shows
    of them: no subcommand module is imported."""
    parser = argparse.ArgumentParser(
        prog="cclog",
        description="cclogfs: keep the robot log data that matters, compressed and checksummed.",
        epilog="Start with `cclog demo`; `cclog COMMAND --help` shows examples for each command.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"cclog {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, help_line in COMMANDS.items():
        if command and name != command:
            continue
        if command == "":  # the list alone: no module needed
            sub.add_parser(name, help=help_line)
            continue
        mod = importlib.import_module(f"{__name__}.{name}")
        p = sub.add_parser(name, help=help_line, description=mod.DESCRIPTION, epilog=mod.EXAMPLES,
                           formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
        mod.add_arguments(p)
        p.set_defaults(func=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # The top-level parser has no options but --help, so a command comes first or not at all.
    command = argv[0] if argv and argv[0] in COMMANDS else ""
    args = None
    try:
        # Inside the try: building the parser imports the subcommand's module, a few tenths
        # of a second in which a Ctrl-C gave a traceback instead of "interrupted".
        args = build_parser(command).parse_args(argv)
        if getattr(args, "max_record_mib", None):
            from ..store import format as store_format  # here: `cclog --help` need not import the store

            store_format.DECODE_RAW_LIMIT = args.max_record_mib << 20
        return int(args.func(args) or 0)
    except CclogError as err:
        from .common import cli_words

        # A hint to pass --skip-damaged names a flag of this command, or commands that have it
        print(f"cclog: error: {cli_words(str(err), skip_damaged='skip_damaged' in vars(args or {}))}",
              file=sys.stderr)  # fmt: skip
        return 1
    except KeyboardInterrupt:
        print("cclog: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    except OSError as err:  # a path the file system refused (NotADirectory, permissions...): say which
        where = " -> ".join(str(p) for p in (err.filename, err.filename2) if p is not None)
        print(f"cclog: error: {where + ': ' if where else ''}{err.strerror or err}", file=sys.stderr)
        return 1
