"""`cclog play STORE`: a store's messages at their recorded pace, as JSONL or on ROS 1 topics."""

from __future__ import annotations

import argparse
import sys
import time

from ..errors import InvalidInputError
from .common import TIME_RULE, check_range, check_store_topics, nothing_matched, refuse_cut_tail, time_arg

# The engine and the players are imported where they are used, not here: `cclog --help`
# imports every subcommand module.

EXAMPLES = """\
examples:
  cclog play robot.store                                   # JSONL on stdout at the recorded pace
  cclog play robot.store --rate 10 --topic /odom | jq .msg.twist
  cclog play robot.store --to ros1:// --clock              # ROS 1 topics (ROS_MASTER_URI), and /clock
  cclog play robot.store --to ros1://localhost:11311 --loop --skip-gaps 2
  cclog play robot.store --foxglove                        # Foxglove app: open ws://localhost:8765

Messages of all chosen streams are merged by stamp and each is sent when its time has come
(stamp differences divided by --rate). With --to ros1:// every stream is published with the
message type it was recorded with (kept in the store by `cclog record`; a store without
types can only be played as JSONL). --skip-gaps S plays any stretch without messages longer
than S seconds as S seconds: smart-logged stores are mostly gaps between windows.
"""

DESCRIPTION = "Play a store back: its messages in time order at their recorded pace."


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("store", help="store directory")
    p.add_argument("--topic", action="append", metavar="T",
                   help="only stream T (repeatable); default: every stream but /cclog/runs")
    p.add_argument("--start", type=time_arg, metavar="TIME", help=f"from this time on ({TIME_RULE})")
    p.add_argument("--end", type=time_arg, metavar="TIME", help="up to this time (inclusive)")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor (default 1: the recorded pace)")
    p.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    p.add_argument("--skip-gaps", type=float, metavar="S", help="play stretches without messages longer than S s as S s")
    p.add_argument("--to", default="-", metavar="-|ros1://[HOST:PORT]",
                   help="- for JSONL on stdout (default), or ros1:// to publish on a ROS 1 master")
    p.add_argument("--clock", action="store_true", help="with --to ros1://: publish /clock with each stamp")
    p.add_argument("--foxglove", nargs="?", type=int, const=8765, metavar="PORT",
                   help="serve the messages over the Foxglove WebSocket protocol on PORT (default 8765)")
    p.add_argument("--host", default="127.0.0.1", help="with --foxglove: the address to listen on (default %(default)s)")
    p.add_argument("--wait-for-subscribers", action="store_true",
                   help="with --to ros1:// or --foxglove: wait until every topic has a subscriber before playing")


def run(args: argparse.Namespace) -> int:
    from ..play.pace import paced, store_messages, stream_types
    from ..runs import hidden_by_default
    from ..store import open_store

    if not args.rate > 0:
        raise InvalidInputError(f"--rate must be positive, not {args.rate}")
    if args.skip_gaps is not None and not 0 <= args.skip_gaps < float("inf"):
        # nan was a traceback; a negative S played every gap backwards: no pacing at all
        raise InvalidInputError(f"--skip-gaps must be a number of seconds >= 0, not {args.skip_gaps}")
    if args.foxglove is not None and args.to != "-":
        raise InvalidInputError("--foxglove and --to ros1:// are two ways to play; choose one")
    if args.to != "-" and not args.to.startswith("ros1://"):
        raise InvalidInputError(f"--to {args.to!r}: write - (stdout) or ros1://[HOST:PORT]")
    _refuse_options_of_other_sinks(args)
    check_range(args)
    with open_store(args.store, readonly=True) as store:
        refuse_cut_tail(store, skip=None)  # no --skip-damaged here: refused outright
        names = sorted(n for n in store.streams() if (n in args.topic if args.topic else not hidden_by_default(n)))
        if not names:
            raise nothing_matched(store, args)
        check_store_topics(store, args)
        types = stream_types(store, names)
        _warn_long_span(store.streams(), names, args)
        send, close = _sink(args, store, names, types)
        progress = PlayProgress(store, names, args)
        n = 0
        try:
            while True:
                for name, stamp, text in paced(store_messages(store, names, args.start, args.end), args.rate,
                                               skip_gaps_s=args.skip_gaps):  # fmt: skip
                    send(name, stamp, text)
                    n += 1
                    progress(stamp)
                if not args.loop or n == 0:
                    break
        finally:
            progress.close()
            close()
    if n == 0:
        with open_store(args.store, readonly=True) as store:
            raise nothing_matched(store, args)
    print(f"played {n:,} messages of {len(names)} streams from {args.store}", file=sys.stderr)
    return 0


def _refuse_options_of_other_sinks(args: argparse.Namespace) -> None:
    """--clock, --host and --wait-for-subscribers belong to one sink each; given to another
    they were ignored without a word (`play --clock` played JSONL with no /clock)."""
    ros1, foxglove = args.to.startswith("ros1://"), args.foxglove is not None
    if args.clock and not ros1:
        raise InvalidInputError("--clock publishes /clock on ROS 1: it goes with --to ros1://")
    if args.host != "127.0.0.1" and not foxglove:
        raise InvalidInputError("--host is the address the Foxglove server listens on: it goes with --foxglove")
    if args.wait_for_subscribers and not (ros1 or foxglove):
        raise InvalidInputError("--wait-for-subscribers goes with --to ros1:// or --foxglove (stdout has no subscribers)")


def _sink(args: argparse.Namespace, store, names: list[str], types: dict):
    """(send(name, stamp, text), close()) for --foxglove or --to."""
    if args.foxglove is not None:
        from ..play.foxglove import FoxgloveServer

        server = FoxgloveServer(store, names, types, host=args.host, port=args.foxglove)
        print(f"foxglove: serving {len(server.channels)} channels on ws://{args.host}:{server.port}", file=sys.stderr,
              flush=True)  # fmt: skip
        if args.wait_for_subscribers:
            server.wait_for_subscribers()
        return server.publish, server.close
    if args.to == "-":
        from ..jsontext.lines import format_line

        out = sys.stdout

        def send(name: str, stamp: int, text: str) -> None:
            out.write(format_line(name, stamp, text, types.get(name, {}).get("msgtype", "")))
            out.flush()  # a reader sees each message at its time

        return send, out.flush
    from ..play.ros1 import Ros1Publisher

    missing = [n for n in names if n not in types]
    if missing and args.topic:
        raise InvalidInputError(f"stream {missing[0]} has no stored message type, so it cannot be published "
                                "on ROS 1 (record it again with `cclog record`)")  # fmt: skip
    if missing:  # e.g. the summary stream: said, and left out
        print(f"cclog: not published (no stored message type): {', '.join(missing)}", file=sys.stderr)
        names[:] = [n for n in names if n in types]
    if not names:
        raise InvalidInputError("no chosen stream has a stored message type, so none can be published on ROS 1")
    pub = Ros1Publisher(args.to, {n: types[n] for n in names}, clock=args.clock)
    if args.wait_for_subscribers:
        pub.wait_for_subscribers()
    return pub.publish, pub.close


class PlayProgress:
    """On a terminal: how far into the selection's time span playback is, and the time
    left at --rate (without --skip-gaps; with it, an upper bound)."""

    def __init__(self, store, names: list[str], args: argparse.Namespace) -> None:
        self.enabled = sys.stderr.isatty()
        self.rate, self._drawn = args.rate, 0.0
        if self.enabled:
            spans = [(w.start_ns, w.end_ns) for n in names for w in store.query(n, start_ns=args.start, end_ns=args.end)]
            self.first = max(min(a for a, _ in spans), args.start or 0) if spans else 0
            self.last = min(max(b for _, b in spans), args.end or 1 << 63) if spans else 0

    def __call__(self, stamp: int) -> None:
        if not self.enabled or (now := time.monotonic()) - self._drawn < 0.25:
            return
        self._drawn = now
        total = max(self.last - self.first, 1)
        done = min(max(stamp - self.first, 0), total)
        left = (total - done) / 1e9 / self.rate
        sys.stderr.write(f"\rplay: {100 * done / total:5.1f} % ({done / 1e9:,.1f} of {total / 1e9:,.1f} s), "
                         f"{left:,.0f} s left\x1b[K")  # fmt: skip
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self._drawn:
            sys.stderr.write("\n")


def _warn_long_span(streams: dict, names: list[str], args: argparse.Namespace) -> None:
    """A note when playing would take over a day: usually streams on different clocks (one in
    simulation time, one in wall time), which play would otherwise wait out in silence."""
    if args.skip_gaps is not None:
        return
    first = max(min(streams[n]["start_ns"] for n in names), args.start or 0)
    last = min(max(streams[n]["end_ns"] for n in names), args.end if args.end is not None else 1 << 63)
    seconds = (last - first) / 1e9 / args.rate
    if seconds > 86400:
        print(f"cclog: note: the chosen messages span {seconds / 86400:,.0f} days at --rate {args.rate:g} "
              "(streams on different clocks?); --skip-gaps S plays long gaps as S seconds", file=sys.stderr)  # fmt: skip
