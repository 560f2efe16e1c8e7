"""Live ROS 1 topics as `SourceMessage`s: what `cclog record ros1://` reads.

rospy subscribes with `rospy.AnyMsg`, so no generated message classes are needed: each
message arrives as its serialized bytes with the connection header (`type`,
`message_definition`, `md5sum`, `latching`), and rosbags decodes the bytes from that
definition, as it decodes a ROS 1 bag, so a live recording holds the same JSON as a
recording of the bag. rospy's receive threads only queue the bytes; decoding runs in the
thread that iterates, so a burst waits in the queue instead of being dropped.

The message's time is its receive time (what `rosbag record` writes as the log time, and
so what a bag recording of the same playback would use); with clock="header" its
`header.stamp`, else its receive time (docs/JSON.md).
"""

from __future__ import annotations

import functools
import glob
import os
import queue
import re
import signal
import sys
import threading
import time
import urllib.parse
from collections.abc import Iterable, Iterator
from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.msg import normalize_msgtype as _normalize

from ..errors import InvalidInputError, SourceError
from ..jsontext.rostypes import TypeCheck, ros1_description
from ..jsontext.ros import MessageConverter, message_stamp_ns
from ..jsontext.roswire import WireFormatter
from .base import SourceMessage, check_clock
from .ros1seq import SeqCheck

# Header stamps this far from the wall clock are on another clock than receive times.
CLOCK_APART_NS = 3600 * 1_000_000_000
INSTALL_HINT = (
    "ROS 1 is not installed (no rospy): on Debian/Ubuntu `sudo apt-get install ros-core python3-rospy "
    "python3-rosbag`, or source a ROS 1 setup.bash"
)
# Where Debian's python3-rospy and a ROS 1 distribution under /opt/ros put rospy.
SYSTEM_PATHS = ("/usr/lib/python3/dist-packages", *sorted(glob.glob("/opt/ros/*/lib/python3/dist-packages")))


def import_rospy(paths: Iterable[str] = SYSTEM_PATHS) -> Any:
    """rospy, from this environment or else from the system's Python packages.

    The system directories go at the END of sys.path, so every package this environment
    has (numpy, rosbags, ...) is still its own; only what it lacks (rospy, genpy, yaml,
    rospkg) comes from the system. Done only when recording or playing live.
    """
    try:
        import rospy
    except ImportError:
        for path in paths:
            if os.path.isdir(path) and path not in sys.path:
                sys.path.append(path)
        try:
            import rospy
        except ImportError as err:
            raise SourceError(f"{INSTALL_HINT} ({err})") from None
    return rospy


def master_uri(uri: str) -> str:
    """The master's XML-RPC URI for a `ros1://[HOST:PORT]` source (empty: ROS_MASTER_URI)."""
    if not uri.startswith("ros1://"):
        raise InvalidInputError(f"{uri!r} is not a ROS 1 source; write ros1:// or ros1://HOST:PORT")
    where = uri[len("ros1://"):].strip("/")
    if where:
        return _checked(f"http://{where}/", uri)
    env = os.environ.get("ROS_MASTER_URI")
    if not env:
        raise SourceError("ros1:// needs a master: set ROS_MASTER_URI (e.g. http://localhost:11311) "
                          "or write ros1://HOST:PORT")  # fmt: skip
    return _checked(env, f"ROS_MASTER_URI={env}")


def _checked(url: str, given: str) -> str:
    """`url` when it is http://HOST[:PORT]/ (rosgraph raises a bare ValueError otherwise)."""
    try:
        parsed = urllib.parse.urlsplit(url)
        ok = parsed.scheme == "http" and bool(parsed.hostname) and " " not in url
        parsed.port  # noqa: B018 - raises ValueError for a port that is not a number
    except ValueError:
        ok = False
    if not ok:
        raise InvalidInputError(f"{given}: not a ROS master URI; write http://HOST:PORT (e.g. ros1://localhost:11311)")
    return url


class TopicMatcher:
    """Which topics to record: each `topics` entry is an exact name or a regular
    expression matched against the whole name; `exclude` entries (regular expressions,
    whole name) win. No `topics`: every topic."""

    def __init__(self, topics: Iterable[str] | None = None, exclude: Iterable[str] = ()) -> None:
        self.names = frozenset(topics or ())
        self.all = topics is None
        self._patterns = [_regex(t, "--topic") for t in self.names]
        self._exclude = [_regex(x, "--exclude") for x in exclude]

    def __call__(self, topic: str) -> bool:
        if any(x.fullmatch(topic) for x in self._exclude):
            return False
        return self.all or topic in self.names or any(p.fullmatch(topic) for p in self._patterns)


def _regex(text: str, flag: str) -> re.Pattern:
    try:
        return re.compile(text)
    except re.error as err:
        raise InvalidInputError(f"{flag} {text!r} is not a valid regular expression: {err}") from None


class Ros1LiveSource:
    """Messages of the matching topics on a running ROS 1 master, until `stop()`.

    Subscribes at once to every exact `topics` name and to what the master lists as
    published, and looks for new matching topics every `poll_s` seconds. `stop()` (or the
    `signal_handler`) ends the iteration once the messages already received are out;
    `close()` unsubscribes and shuts the node down (rospy allows one node per process).
    """

    def __init__(self, uri: str = "ros1://", *, topics: Iterable[str] | None = None, exclude: Iterable[str] = (),
                 node_name: str = "cclog_record", poll_s: float = 0.5, idle_s: float = 0.3,
                 clock: str = "log") -> None:  # fmt: skip
        self.name = uri
        self._header_clock = check_clock(clock) == "header"
        self.master = master_uri(uri)
        self.matcher = TopicMatcher(topics, exclude)
        self.poll_s, self.idle_s = poll_s, idle_s
        self.received: dict[str, int] = {}
        self.seq = SeqCheck()  # messages lost, told from header.seq: `seq.lost`, `seq.lines()`
        self.types = TypeCheck()  # `types.refused`: messages of another type than their stream's, not stored
        self.stopped_by: str | None = None
        self._master_lost = False
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._subs: dict[str, Any] = {}
        self._conns: dict[str, dict[str, Any]] = {}  # topic -> its first connection header
        self._typestores: dict[str, Any] = {}  # md5sum -> a type store with that definition
        self._converter = MessageConverter()
        self._wires: dict[int, WireFormatter] = {}  # id(type store) -> its formatters
        self._stamped: tuple[str, int] | None = None  # a topic with header stamps, and receive time - stamp
        self._unstamped: set[str] = set()  # topics stored at their receive time
        self._clock_checked: set[str] = set()
        self._clock_said: set[str] = set()
        self._rospy = import_rospy()
        self._start_node(node_name)

    def _start_node(self, node_name: str) -> None:
        import rosgraph

        if not rosgraph.is_master_online(self.master):
            raise SourceError(f"no ROS master answers at {self.master}: start roscore, or set ROS_MASTER_URI")
        os.environ["ROS_MASTER_URI"] = self.master  # rospy reads it from the environment
        # disable_signals: Ctrl-C and SIGTERM stay with the program (the CLI flushes on them);
        # disable_rostime: the receive time is the wall clock, whatever /clock says.
        self._rospy.init_node(node_name, anonymous=True, disable_signals=True, disable_rostime=True)
        for topic in sorted(self.matcher.names):
            if not _is_pattern(topic) and self.matcher(topic):
                self._subscribe(topic)

    # -- receiving ---------------------------------------------------------------------

    def _subscribe(self, topic: str) -> None:
        # queue_size=None: rospy keeps every message it receives (a bounded queue drops the
        # oldest, silently). The cost is memory: while decoding lags, the backlog grows.
        self._subs[topic] = self._rospy.Subscriber(topic, self._rospy.AnyMsg, self._received, callback_args=topic,
                                                   queue_size=None, buff_size=1 << 20)  # fmt: skip
        self.received.setdefault(topic, 0)  # a topic that delivers nothing is reported too

    def _received(self, msg: Any, topic: str) -> None:
        # In rospy's receive thread: take the time and the bytes, nothing more.
        self._queue.put((topic, time.time_ns(), msg._buff, msg._connection_header))

    def discover(self) -> list[str] | None:
        """Subscribe to the matching topics the master lists that are not subscribed yet;
        the topics it lists (None when it does not answer)."""
        try:
            published = self._rospy.get_published_topics()
        except Exception as err:  # the master went away: keep what is subscribed, say so once
            if not self._master_lost:
                print(f"cclog: cannot list topics at {self.master} (recording goes on): {err}", file=sys.stderr)
            self._master_lost = True
            return None
        if self._master_lost:
            print(f"cclog: {self.master} answers again", file=sys.stderr)
            self._master_lost = False
        for topic, _ in published:
            if topic not in self._subs and self.matcher(topic):
                self._subscribe(topic)
        return [t for t, _ in published]

    def stop(self) -> None:
        """End the iteration after the messages already received (thread- and signal-safe)."""
        self._stop.set()
        self._queue.put(None)  # wakes the iteration at once

    def signal_handler(self, signum: int, frame: Any) -> None:
        """For SIGINT/SIGTERM: the first stops the recording cleanly, a second interrupts."""
        if self._stop.is_set():
            raise KeyboardInterrupt
        self.stopped_by = signal.Signals(signum).name
        self.stop()

    def __iter__(self) -> Iterator[SourceMessage]:
        # Blocks until a message, the next look for topics, or stop(): no busy polling.
        listed = self.discover()
        if not self._subs and listed is not None:  # else the user waits on nothing, in silence
            print(f"{self.name}: no topic on the master matches (published now: {', '.join(sorted(listed)) or 'none'}); "
                  "waiting for one, Ctrl-C to stop", file=sys.stderr, flush=True)  # fmt: skip
        next_poll = time.monotonic() + self.poll_s
        while True:
            stopping = self._stop.is_set()
            if stopping and self._subs:
                # Stop receiving first: a topic that keeps publishing would never let the
                # queue fall idle. What rospy already holds still arrives within idle_s.
                self._unsubscribe()
            try:
                # Once stopping, end when nothing has come for idle_s: rospy may still hold a few.
                item = self._queue.get(timeout=self.idle_s if stopping else max(0.0, next_poll - time.monotonic()))
            except queue.Empty:
                if stopping:
                    return
                item = None
            if item is not None and (message := self._convert(*item)) is not None:
                yield message
            if not stopping and time.monotonic() >= next_poll:
                self.discover()
                next_poll = time.monotonic() + self.poll_s

    def _convert(self, topic: str, recv_ns: int, raw: bytes, header: dict[str, str]) -> SourceMessage | None:
        """The message, or None for one of another type than its stream's (a publisher
        restarted with another type): skipped, said once per topic, counted in `types.refused`;
        stopping would lose the rest of a live recording."""
        msgtype = normalize_msgtype(header["type"])
        if (why := self.types.mismatch(topic, msgtype)) is not None:
            if self.types.refused[topic] == 1:
                print(f"cclog: warning: {self.name}: {why}; skipping its messages of type {msgtype} (counted at the "
                      "end)", file=sys.stderr, flush=True)  # fmt: skip
            return None
        self.seq.add(topic, raw, header)
        if topic not in self._conns:
            self._conns[topic] = header
        typestore = self._typestore(topic, msgtype, header)
        text, stamp = self._text(topic, msgtype, recv_ns, raw, typestore)
        self.received[topic] = self.received.get(topic, 0) + 1
        stamp = stamp if self._header_clock else 0
        if self._header_clock:  # header stamps and receive times mixed: say when they are far apart
            self._note_clock(topic, stamp, recv_ns)
        return SourceMessage(topic, stamp or recv_ns, text, msgtype)

    def _text(self, topic: str, msgtype: str, recv_ns: int, raw: bytes, typestore: Any) -> tuple[str, int | None]:
        """(JSON text, header stamp) of a message: through the type's generated formatter
        (jsontext.roswire, as RosbagSource), else, or when it refuses the bytes, through
        rosbags' objects, whose error is the one reported."""
        wire = self._wires.get(id(typestore))
        if wire is None:
            wire = self._wires[id(typestore)] = WireFormatter(typestore, cdr=False)
        if (done := wire.format(msgtype, raw)) is not None:
            return done
        try:
            msg = wire.deserialize(msgtype, raw)
        except Exception as err:
            raise SourceError(f"{self.name}: cannot decode the {msgtype} message on {topic} "
                              f"received at {recv_ns} ns: {err}") from err  # fmt: skip
        return self._converter.to_json(msg), message_stamp_ns(msg)

    def _note_clock(self, topic: str, stamp: int, recv_ns: int) -> None:
        if stamp:
            self._stamped = (topic, recv_ns - stamp)
        elif topic not in self._unstamped:
            self._unstamped.add(topic)
            self._check_clocks(topic)
        if self._stamped is not None and self._stamped[0] not in self._clock_checked:
            self._clock_checked.add(self._stamped[0])
            for other in sorted(self._unstamped):
                self._check_clocks(other)

    def _check_clocks(self, topic: str) -> None:
        """Say so when `topic` (no header stamp: stored at its receive time) and the header
        stamps of another topic are on clocks far apart (a bag played without its clock):
        the two never meet in one window or one playback."""
        if self._stamped is None or abs(self._stamped[1]) < CLOCK_APART_NS or topic in self._clock_said:
            return
        self._clock_said.add(topic)
        hours = abs(self._stamped[1]) / 3600e9
        apart = f"{hours:,.0f} hours" if hours < 48 else f"{hours / 24:,.0f} days"
        print(f"{self.name}: {topic} has no header stamp, so it is stored at its receive time (wall clock), but the "
              f"header stamps of {self._stamped[0]} are {apart} away from it: "
              f"{topic} is on another clock (a bag played without --clock?); smart logging's windows will not hold "
              "it", file=sys.stderr, flush=True)  # fmt: skip

    def _typestore(self, topic: str, msgtype: str, header: dict[str, str]) -> Any:
        """A type store that knows `msgtype` as this connection defines it (one per MD5: two
        publishers may disagree on a type's definition)."""
        md5 = header.get("md5sum", "")
        store = self._typestores.get(md5)
        if store is None:
            store = get_typestore(Stores.EMPTY)
            try:
                store.register(get_types_from_msg(header.get("message_definition", ""), msgtype))
            except Exception as err:
                raise SourceError(f"{self.name}: the definition of {msgtype} on {topic} cannot be parsed: {err}") from err
            self._typestores[md5] = store
        return store

    # -- what a recording stores about the streams -------------------------------------

    def topics(self) -> dict[str, str]:
        return {t: normalize_msgtype(h["type"]) for t, h in self._conns.items()}

    def describe(self, topic: str) -> dict:
        """The ROS 1 definition of `topic`'s type, as its publisher sent it."""
        header = self._conns.get(topic)
        if header is None:
            return {}
        msgtype = normalize_msgtype(header["type"])
        return ros1_description(self._typestores.get(header.get("md5sum", "")), msgtype,
                                msgdef=header.get("message_definition", ""), md5sum=header.get("md5sum", ""),
                                latching=header.get("latching") == "1")  # fmt: skip

    # -- lifetime ----------------------------------------------------------------------

    def _unsubscribe(self) -> None:
        for sub in self._subs.values():
            sub.unregister()
        self._subs.clear()

    def close(self) -> None:
        self._unsubscribe()
        # What arrived after the iteration ended (or was cut short) is not stored: say so.
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                break
            if item is not None:
                self.seq.add(item[0], item[2], item[3])
                self.seq.not_stored += 1
        self._rospy.signal_shutdown("cclog: recording ended")

    def __enter__(self) -> Ros1LiveSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@functools.lru_cache(maxsize=1024)
def normalize_msgtype(name: str) -> str:
    """nav_msgs/Odometry -> nav_msgs/msg/Odometry, cached: rosbags' goes through pathlib,
    which was the largest cost per message after decoding."""
    return _normalize(name)


def _is_pattern(topic: str) -> bool:
    """True for a --topic that is a regular expression rather than a topic name."""
    return not re.fullmatch(r"[A-Za-z0-9_/~]+", topic)
