"""The `cclog` command line. Each subcommand is a module in this package that defines
HELP, DESCRIPTION, EXAMPLES, `add_arguments(parser)` and `run(args)`; the module list
below is the only place that names them."""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import CclogError

# One module per subcommand, in the order `cclog --help` lists them.
COMMANDS: list[str] = ["demo", "record", "play", "plot", "cat", "info", "fsck", "compact", "export", "convert", "simulate", "train", "eval"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cclog",
        description="cclogfs: keep the robot log data that matters, compressed and checksummed.",
        epilog="Start with `cclog demo`; `cclog COMMAND --help` shows examples for each command.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"cclog {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        mod = importlib.import_module(f"{__name__}.{name}")
        p = sub.add_parser(name, help=mod.HELP, description=mod.DESCRIPTION, epilog=mod.EXAMPLES,
                           formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
        mod.add_arguments(p)
        p.set_defaults(func=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CclogError as err:
        print(f"cclog: error: {_cli_words(str(err))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("cclog: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


# The store's errors name its Python API; on the command line they name the command.
_API_WORDS = {
    "pass create=True to make one": "`cclog record SOURCE --store PATH` makes one",
    "open it with readonly=True to read": "commands that only read (info, cat, export, play) work meanwhile",
}


def _cli_words(message: str) -> str:
    for api, cli in _API_WORDS.items():
        message = message.replace(api, cli)
    return message
