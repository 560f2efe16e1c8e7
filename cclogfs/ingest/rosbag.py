"""ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage) and ROS 2 MCAP files, through rosbags.

rosbags needs no ROS install: it builds its type store from the message definitions
stored in the bag, so every message type the bag describes can be read.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.interfaces import ConnectionExtRosbag1, MessageDefinitionFormat

from ..errors import SourceError
from ..jsontext.ros import message_stamp_ns
from ..jsontext.rostypes import ros1_description
from .base import SourceMessage, check_clock, topic_filter
from ..jsontext.ros import MessageConverter


class RosbagSource:
    """Messages of a rosbag (any kind `AnyReader` opens), in log-time order.

    `stamp_ns` is the bag's log (receive) time, one clock for every topic as rosbag2 uses
    it; with clock="header" it is the message's `header.stamp`, and messages without a
    header, or whose stamp is zero (ROS's "not set", common on /tf_static), get the log
    time. The header stamp always stays in the message's JSON.
    """

    def __init__(self, path: str | Path, *, topics: Iterable[str] | None = None, clock: str = "log") -> None:
        self.name = str(path)
        self._header_clock = check_clock(clock) == "header"
        self._wanted = topic_filter(topics)
        try:
            self._reader = AnyReader([Path(path)])
            self._reader.open()
        except Exception as err:  # rosbags raises several unrelated types for a bad bag
            raise SourceError(f"Cannot open {self.name} as a rosbag: {err}") from err
        self._connections = [
            c
            for c in self._reader.connections
            if self._wanted is None or c.topic in self._wanted
        ]

    def __enter__(self) -> RosbagSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._reader.stack is not None:
            self._reader.close()

    def topics(self) -> dict[str, str]:
        return {c.topic: c.msgtype for c in self._connections}

    @property
    def message_count(self) -> int:
        """How many messages iterating will yield (from the bag's index), for progress."""
        return sum(c.msgcount for c in self._connections)

    def describe(self, topic: str) -> dict:
        """The ROS 1 definition of `topic`'s type, for window metadata (`jsontext.rostypes`)."""
        for c in self._connections:
            if c.topic == topic:
                ros1 = c.msgdef.format == MessageDefinitionFormat.MSG and isinstance(c.ext, ConnectionExtRosbag1)
                return ros1_description(self._reader.typestore, c.msgtype, msgdef=c.msgdef.data if ros1 else "",
                                        md5sum=c.digest if ros1 else "", latching=ros1 and bool(c.ext.latching))
        return {}

    def __iter__(self) -> Iterator[SourceMessage]:
        if not self._connections:
            return
        reader = self._reader
        deserialize = reader.deserialize
        to_json = MessageConverter().to_json
        try:
            for con, logtime, raw in reader.messages(connections=self._connections):
                try:
                    msg = deserialize(raw, con.msgtype)
                except Exception as err:
                    raise SourceError(
                        f"{self.name}: cannot decode the {con.msgtype} message on {con.topic} "
                        f"logged at {logtime} ns: {err}"
                    ) from err
                stamp = message_stamp_ns(msg) if self._header_clock else 0
                yield SourceMessage(con.topic, stamp or logtime, to_json(msg), con.msgtype)
        except SourceError:
            raise
        except Exception as err:
            raise SourceError(f"{self.name}: reading the bag failed: {err}") from err
