"""ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage) and ROS 2 MCAP files, through rosbags.

rosbags needs no ROS install: it builds its type store from the message definitions
stored in the bag, so every message type the bag describes can be read. rosbags opens the
bag and reads its index; the messages' bytes become JSON through formatters generated per
type from that type store (jsontext.roswire), and a ROS 1 bag's records are read from its
chunks by ros1chunks (issue 14: 4x faster than rosbags' objects and json.dumps).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import ConnectionExtRosbag1, MessageDefinitionFormat
from rosbags.rosbag1 import Reader as Bag1Reader

from ..errors import SourceError
from ..jsontext.ros import MessageConverter, message_stamp_ns
from ..jsontext.roswire import WireError, WireFormatter
from ..jsontext.rostypes import TypeCheck, ros1_description
from . import mcapchunks, ros1chunks
from .base import BadMessages, OnError, SourceMessage, check_clock, topic_filter
from .mcapbad import BadChunks


class RosbagSource:
    """Messages of a rosbag (any kind `AnyReader` opens), in log-time order.

    `stamp_ns` is the bag's log (receive) time, one clock for every topic as rosbag2 uses
    it; with clock="header" it is the message's `header.stamp`, and messages without a
    header, or whose stamp is zero (ROS's "not set", common on /tf_static), get the log
    time. The header stamp always stays in the message's JSON.
    """

    def __init__(self, path: str | Path, *, topics: Iterable[str] | None = None, clock: str = "log",
                 on_error: OnError = "stop", report: Callable[[SourceError], None] | None = None,
                 types: TypeCheck | None = None) -> None:  # fmt: skip
        self.name = str(path)
        self._bad = BadMessages(on_error, report)  # a message `types` refuses (another type than its topic's first...)
        self._types = types
        self._header_clock = check_clock(clock) == "header"
        self._wanted = topic_filter(topics)
        self._converter: MessageConverter | None = None
        self._bad_chunks = BadChunks(self.name, on_error)  # MCAP chunks that could not be read
        self._short: str | None = None  # a ROS 2 sqlite3 bag that gave fewer messages than its metadata counts
        try:
            self._reader = AnyReader([Path(path)])
            if not self._reader.is2:  # the same reader, its index read faster (issue 14)
                self._reader.readers = [ros1chunks.IndexedReader(p) for p in self._reader.paths]
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
    def skipped(self) -> int:
        """Bad messages skipped (on_error="skip")."""
        return self._bad.skipped

    @property
    def lost(self) -> str | None:
        """What damage lost (chunks of an MCAP file skipped; messages a ROS 2 bag's metadata counts
        that its files lack), None when nothing was."""
        lost = [why for why in (self._bad_chunks.lost, self._short) if why]
        return "; ".join(lost) if lost else None

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
        # One formatter per message type, generated from the bag's own definitions: bytes
        # straight to JSON text (jsontext.roswire), 4-5x faster than rosbags objects +
        # json.dumps; types it cannot format take that path (`_convert`).
        wire = WireFormatter(reader.typestore, cdr=reader.is2)
        formats = {c.id: wire.get(c.msgtype) for c in self._connections}
        header_clock = self._header_clock
        # SourceMessage(...) runs the named tuple's Python-level __new__; tuple.__new__
        # builds the same object in C, 0.5 us less per message (issue 14).
        make = tuple.__new__
        types = self._types if self._types is not None else TypeCheck()
        mixed = self._mixed_types(types)
        index = 0
        try:
            for con, logtime, raw in self._raw_messages():
                index += 1
                if con.id in mixed and (why := types.mismatch(con.topic, con.msgtype)) is not None:
                    self._bad(SourceError(f"{self.name}, message {index:,} of the bag (logged at {logtime} ns): {why}"))
                    continue
                fmt = formats[con.id]
                if fmt is None:
                    text, stamp = self._convert(con, logtime, raw, index, None)
                else:
                    try:
                        text, stamp = fmt(raw)
                    except WireError as err:
                        text, stamp = self._convert(con, logtime, raw, index, err)
                yield make(SourceMessage, (con.topic, (header_clock and stamp) or logtime, text, con.msgtype))
            self._short = _short_of_metadata(self._reader, self.message_count, index)
        except SourceError:
            raise
        except Exception as err:
            raise SourceError(f"{self.name}: reading the bag failed: {err}") from err

    def _mixed_types(self, types: TypeCheck) -> set[Any]:
        """The ids of the connections whose topic has connections of more than one type,
        or that `types` watches (reserved, typed in the store): only their messages need
        checking against the stream's type."""
        by_topic: dict[str, set[str]] = {}
        for c in self._connections:
            by_topic.setdefault(c.topic, set()).add(c.msgtype)
        return {c.id for c in self._connections if len(by_topic[c.topic]) > 1 or types.watches(c.topic)}

    def _raw_messages(self) -> Iterator[tuple[Any, int, bytes]]:
        """(connection, log time, bytes) of the selected topics, in log-time order. A ROS 1
        bag's are read from its chunks by `ros1chunks` (rosbags' reader, 3-4x slower per
        message, is the reference it is tested against); other kinds by rosbags."""
        readers = self._reader.readers
        if len(readers) == 1 and isinstance(readers[0], Bag1Reader):
            return ros1chunks.messages(readers[0], self._connections, self.name)
        if len(readers) == 1 and (storage := mcapchunks.is_indexed_mcap(readers[0])) is not None:
            return mcapchunks.messages(storage, self._connections, self._bad_chunk)
        return self._reader.messages(connections=self._connections)

    def _bad_chunk(self, chunk: Any, why: str) -> None:
        """An MCAP chunk that cannot be read: the error (default), or skipped and counted."""
        count = None if mcapchunks.unindexed(chunk) else mcapchunks.expected(chunk, {c.id for c in self._connections})
        self._bad_chunks(chunk, why, count)

    def _convert(self, con: Any, logtime: int, raw: bytes, index: int,
                 err: WireError | None) -> tuple[str, int | None]:
        """A message through rosbags' objects and ros.MessageConverter: for types the
        generated formatters do not handle, and to give rosbags the last word on bytes a
        formatter refused (the two agree on every message tested; if they ever did not,
        rosbags' reading is the reference). A message neither can read is an error naming
        the file, the message's place in the bag, and the field when known."""
        if self._converter is None:
            self._converter = MessageConverter()
        try:
            msg = self._reader.deserialize(raw, con.msgtype)
        except Exception as slow:
            where = err or slow  # the formatter names the field
            raise SourceError(
                f"{self.name}: cannot decode message {index:,} of the bag ({con.msgtype} on {con.topic}, "
                f"logged at {logtime} ns): {where}"
            ) from slow
        return self._converter.to_json(msg), message_stamp_ns(msg)


def _short_of_metadata(reader: AnyReader, counted: int, read: int) -> str | None:
    """What a ROS 2 sqlite3 bag lacks when its .db3 files gave fewer messages than its
    metadata.yaml counts (`counted`, of the selected topics): a split file metadata.yaml
    does not list (which the bag reader does not open), rows lost; None when none lack.
    MCAP storage is held against its own statistics (`mcapchunks`), ROS 1 bags are read by
    their index."""
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

    storage = getattr(reader.readers[0], "storage", None) if len(reader.readers) == 1 else None
    storages = getattr(storage, "storages", None)
    if read >= counted or not storages or not all(isinstance(s, Sqlite3Reader) for s in storages):
        return None
    listed = {Path(f["path"]).name for f in storage.files}
    unlisted = sorted(f.name for f in Path(storage.path).glob("*.db3") if f.name not in listed)
    why = (f"; {', '.join(unlisted)} in the directory {'is' if len(unlisted) == 1 else 'are'} not listed in "
           "metadata.yaml, so not read (list it there, or move metadata.yaml away to read every .db3)"
           if unlisted else "")  # fmt: skip
    return (f"{storage.path}: metadata.yaml counts {counted:,} messages, its .db3 files hold {read:,}: "
            f"{counted - read:,} missing{why}")
