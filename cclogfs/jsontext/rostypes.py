"""Each stream's message type, kept in the metadata of the windows a recording stores.

Every window of a stream gets `"msgtype"` (the ROS 2 spelling, `nav_msgs/msg/Odometry`, as
rosbags names types; the MCAP export uses it as the schema name). The first window a
recording run stores of each stream also gets what a player needs to publish the stream
again with its original type: `"msgdef"` (the ROS 1 message definition text, dependencies
included, as a ROS 1 connection header carries it), `"md5sum"` and `"latching"`. Once per run
rather than in every window: the definition of an Odometry is 4 kB, more than a smart-logged
window of it. `play` looks for the first window that has it, and falls back to the types
rosbags ships (ROS 1 Noetic) when the window holding it was dropped.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any

from ..errors import InvalidInputError

Describe = Callable[[str], Mapping[str, Any] | None]

# A record's metadata is at most 64 KiB (docs/FORMAT.md); a definition larger than this is
# left out (play then uses rosbags' types), so that no window is ever refused for it.
MAX_MSGDEF = 32 * 1024


def type_mismatch(types: dict[str, str], topic: str, msgtype: str) -> str | None:
    """None when a message of `msgtype` on `topic` fits its stream in `types` (topic -> the
    first type seen, which this adds; an unnamed type always fits); else why not. A stream
    keeps one type: export and play read all its windows as the type its windows name."""
    if not msgtype:
        return None
    first = types.setdefault(topic, msgtype)
    if first == msgtype:
        return None
    return (f"the message on {topic} is a {msgtype}, but the stream {topic} has type {first} (its first "
            "message's); a stream keeps one type, so record this topic's other type into another store")


def reserved_refusal(topic: str) -> str:
    """Why a source message on `topic`, a stream the recording writes itself (its runs, its
    summary), is refused: stored there, `cat` would leave it out as bookkeeping and
    `cclog info` read it as a run. One wording for the sources and the pipeline's backstop."""
    return f"the message is on {topic}, the stream this recording writes itself; leave that topic out with --topic"


class TypeCheck:
    """For a source: topic -> its stream's type, and the messages refused for another type.

    The one check of a message's topic before it is stored, so that the source names the
    line (or skips it with --on-error skip): `reserved`, the streams the recording writes
    itself (`reserved_refusal`), and `stored`, topic -> the type its stream has in the store
    recorded into (an earlier run's), which a message of another type may not join either."""

    def __init__(self, *, reserved: Iterable[str] = (), stored: Mapping[str, str] | None = None) -> None:
        self.types: dict[str, str] = {}
        self.reserved = frozenset(reserved)
        self.stored: dict[str, str] = dict(stored or {})
        self.refused: dict[str, int] = {}  # topic -> messages refused

    def watches(self, topic: str) -> bool:
        """Whether a message on `topic` may be refused whatever the source's other types."""
        return topic in self.reserved or topic in self.stored

    def mismatch(self, topic: str, msgtype: str) -> str | None:
        """Why a message of `msgtype` on `topic` cannot be stored (None: it can), counting
        each refused message: a reserved topic, then the store's type, then `type_mismatch`."""
        why = self._why(topic, msgtype)
        if why is not None:
            self.refused[topic] = self.refused.get(topic, 0) + 1
        return why

    def _why(self, topic: str, msgtype: str) -> str | None:
        if topic in self.reserved:
            return reserved_refusal(topic)
        stored = self.stored.get(topic)
        if msgtype and stored and stored != msgtype:
            return (f"the message on {topic} is a {msgtype}, but the stream {topic} has type {stored} in the store "
                    "(recorded by an earlier run); a stream keeps one type, so record this topic's other type "
                    "into another store")  # fmt: skip
        return type_mismatch(self.types, topic, msgtype)


class StreamTypes:
    """Topic -> message type as messages come in; adds them to window metadata.

    `stored`: topic -> the type its stream has in the store recorded into, which a window
    of untyped messages (JSONL without msgtype) names too, as after a typed line of the
    same input: a window naming no type would hide the stream's type from the next run."""

    def __init__(self, describe: Describe | None = None, stored: Mapping[str, str] | None = None) -> None:
        self.types: dict[str, str] = dict(stored or {})
        self._describe = describe
        self._described: set[str] = set()

    def saw(self, topic: str, msgtype: str) -> None:
        """Note a message's type; InvalidInputError for one its stream cannot keep (the
        sources refuse those first, naming the line: this is for any other caller)."""
        if (why := type_mismatch(self.types, topic, msgtype)) is not None:
            raise InvalidInputError(why)

    def meta(self, topic: str, meta: Mapping[str, Any]) -> Mapping[str, Any]:
        """`meta` with the stream's type added (and its definition, the first time)."""
        msgtype = self.types.get(topic)
        if not msgtype:
            return meta
        out = {**meta, "msgtype": msgtype}
        if topic not in self._described and self._describe is not None:
            self._described.add(topic)
            extra = dict(self._describe(topic) or {})
            if len(extra.get("msgdef", "").encode()) > MAX_MSGDEF:
                extra.pop("msgdef")
            out.update(extra)
        return out


def ros1_typestore(typestore: Any = None) -> Any:
    """A ROS 1 type store: rosbags' ROS 1 Noetic types, plus the types of `typestore` that
    Noetic lacks. A ROS 2 type so gets a ROS 1 header (with `seq`) wherever it has one."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    if typestore is not None:
        ts.register({k: v for k, v in typestore.fielddefs.items() if k not in ts.fielddefs})
    return ts


def ros1_description(typestore: Any, msgtype: str, *, msgdef: str = "", md5sum: str = "",
                     latching: bool = False) -> dict[str, Any]:  # fmt: skip
    """The metadata a ROS 1 player needs for `msgtype`: the definition and MD5 given (from a
    ROS 1 connection), else those of `ros1_typestore(typestore)`. {} when neither can be had."""
    if not msgdef or not md5sum:
        try:
            msgdef, md5sum = ros1_typestore(typestore).generate_msgdef(msgtype, ros_version=1)
        except Exception:  # a type rosbags cannot express in ROS 1 (some ROS 2 IDL types)
            return {}
    out: dict[str, Any] = {"msgdef": msgdef, "md5sum": md5sum}
    if latching:
        out["latching"] = True
    return out
