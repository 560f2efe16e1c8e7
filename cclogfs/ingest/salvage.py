"""Reading what can be read of a damaged ROS 1 bag or MCAP file (cut short by a power loss,
never indexed), record by record from the start, as `rosbag reindex` and `mcap recover` do.

Used when the indexed readers refuse the file. Messages come in file order (a ROS 1 bag's
chunks and an MCAP's chunks are written in time order). After iterating, `lost` says where
reading stopped and what was lost (None when the whole file was read).
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from ..jsontext.ros import MessageConverter, message_stamp_ns
from ..jsontext.roswire import WireFormatter
from .base import SourceMessage, check_clock, topic_filter

_MSGDATA, _CHUNK, _CONNECTION = 2, 5, 7


class _Salvage:
    """What both salvage readers share: topic filter, clock, the report of what was lost."""

    def __init__(self, path: str | Path, *, topics: Iterable[str] | None = None, clock: str = "log",
                 why: str = "") -> None:  # fmt: skip
        self.name = str(path)
        self._wanted = topic_filter(topics)
        self._header_clock = check_clock(clock) == "header"
        self.why = why
        self.size = os.path.getsize(path)
        self.lost: str | None = None
        self.note: str | None = None
        self._types: dict[str, str] = {}
        self._typestore: Any = None
        self._convert = MessageConverter().to_json

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def topics(self) -> dict[str, str]:
        """Unknown until read (the index is what is damaged): only the selection."""
        return dict.fromkeys(sorted(self._wanted or ()), "")

    def _message(self, topic: str, msgtype: str, logtime: int, msg: Any) -> SourceMessage:
        stamp = message_stamp_ns(msg) if self._header_clock else 0
        return SourceMessage(topic, stamp or logtime, self._convert(msg), msgtype)

    def _from_bytes(self, topic: str, msgtype: str, logtime: int, raw: bytes, wire: WireFormatter) -> SourceMessage:
        """The message in `raw`: through the type's generated formatter (as RosbagSource),
        else, or when it refuses the bytes, through rosbags' objects (whose error stops
        the salvage at this message)."""
        if (done := wire.format(msgtype, raw)) is not None:
            text, stamp = done
            return SourceMessage(topic, (self._header_clock and stamp) or logtime, text, msgtype)
        return self._message(topic, msgtype, logtime, wire.deserialize(msgtype, raw))

    def _stopped(self, offset: int, last_ns: int | None, count: int, err: Exception) -> None:
        if offset >= self.size and isinstance(err, EOFError) and str(err) == "end of file":
            return
        upto = f"the last logged at {last_ns} ns" if last_ns is not None else "none"
        self.lost = (f"{self.name} is damaged ({self.why or err}): read {count:,} messages ({upto}); from the "
                     f"record at byte {offset:,} to the end ({self.size:,} bytes) the file could not be read: {err}")  # fmt: skip


class Ros1Salvage(_Salvage):
    """A ROS 1 bag read chunk by chunk without its index."""

    def __iter__(self) -> Iterator[SourceMessage]:
        from rosbags.rosbag1.reader import Header, decompressors, read_bytes, read_uint32
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        store = get_typestore(Stores.EMPTY)
        wire = WireFormatter(store, cdr=False)
        conns: dict[int, tuple[str, str]] = {}
        count, last, offset = 0, None, 0
        with open(self.name, "rb") as f:
            try:
                f.readline()  # the magic line
                Header.read(f)  # the bag header record, and its padding
                read_bytes(f, read_uint32(f))
                while True:
                    offset = f.tell()
                    if offset >= self.size:
                        raise EOFError("end of file")
                    header = Header.read(f)
                    size = read_uint32(f)
                    data = f.read(size)
                    if header.get_uint8("op") != _CHUNK:
                        if len(data) < size:
                            raise EOFError(f"a record is cut short at byte {f.tell():,}")
                        continue
                    compression = header.get_string("compression")
                    if len(data) < size and compression != "none":
                        raise EOFError(f"a {compression} chunk is cut short at byte {f.tell():,}")
                    # An uncompressed chunk cut short still holds whole records up to the cut.
                    inner = io.BytesIO(decompressors[compression](data))
                    while inner.tell() < len(inner.getbuffer()):
                        h = Header.read(inner)
                        body = read_bytes(inner, read_uint32(inner))
                        op = h.get_uint8("op")
                        if op == _CONNECTION:
                            fields = Header.read(io.BytesIO(len(body).to_bytes(4, "little") + body))
                            msgtype = fields.get_string("type").replace("/", "/msg/", 1)
                            if msgtype not in store.fielddefs:
                                store.register(get_types_from_msg(fields.get_string("message_definition"), msgtype))
                            conns[h.get_uint32("conn")] = (h.get_string("topic"), msgtype)
                        elif op == _MSGDATA:
                            topic, msgtype = conns[h.get_uint32("conn")]
                            if self._wanted is None or topic in self._wanted:
                                last = h.get_time("time")
                                count += 1
                                yield self._from_bytes(topic, msgtype, last, body, wire)
                    if len(data) < size:
                        raise EOFError(f"a chunk is cut short at byte {f.tell():,}")
            except (EOFError, Exception) as err:  # rosbags raises ReaderError, struct.error, KeyError...
                self._stopped(offset, last, count, err)


def _statistics(records: Iterator[Any], kind: type) -> Any:
    """The Statistics record of an MCAP summary section (what is read after DataEnd), or
    None. Only its counts are taken, to hold the messages read against: the summary's
    schemas and channels are not (no chunk CRC covers them, and the file is damaged)."""
    try:
        for rec in records:
            if isinstance(rec, kind):
                return rec
    except Exception:  # a damaged summary: no counts to check against
        return None
    return None


class McapSalvage(_Salvage):
    """A ROS 2 MCAP file (CDR messages, ros2msg schemas) read as a stream of records."""

    def __iter__(self) -> Iterator[SourceMessage]:
        from mcap.records import Channel, DataEnd, Message, Schema, Statistics
        from mcap.stream_reader import StreamReader
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        store = get_typestore(Stores.EMPTY)
        wire = WireFormatter(store, cdr=True)
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        count, last = 0, None
        found: dict[int, int] = {}  # channel id -> messages read, to hold against the file's statistics
        stats = None
        with open(self.name, "rb") as f:
            records = StreamReader(f, record_size_limit=self.size).records
            try:
                for rec in records:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec.name
                        if rec.encoding == "ros2msg" and rec.name not in store.fielddefs:
                            store.register(get_types_from_msg(rec.data.decode(), rec.name))
                    elif isinstance(rec, Channel):
                        channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ""))
                    elif isinstance(rec, Message):
                        topic, msgtype = channels[rec.channel_id]
                        found[rec.channel_id] = found.get(rec.channel_id, 0) + 1
                        if self._wanted is None or topic in self._wanted:
                            last = rec.log_time
                            count += 1
                            yield self._from_bytes(topic, msgtype, last, rec.data, wire)
                    elif isinstance(rec, DataEnd):  # the summary repeats schemas and channels: no message
                        stats = _statistics(records, Statistics)
                        break
                raise EOFError("end of file")
            except (EOFError, Exception) as err:
                self._stopped(f.tell() if not isinstance(err, EOFError) else self.size, last, count, err)
        if self.lost is None and stats is not None:
            self._missing(stats.channel_message_counts, found, channels, count)
        if self.lost is None and self.why:  # nothing lost, but the file is damaged: say so (`cli.common.damaged_exit`)
            self.note = f"{self.name}: {self.why}; read record by record instead: every message read ({count:,})"

    def _missing(self, counted: dict[int, int], found: dict[int, int], channels: dict[int, tuple[str, str]],
                 count: int) -> None:  # fmt: skip
        """Read to its end, but fewer messages than the file's statistics count (a chunk cut
        out of the file leaves no trace but that): say what is missing."""
        short = {cid: n - found.get(cid, 0) for cid, n in counted.items() if n > found.get(cid, 0)
                 and (self._wanted is None or channels.get(cid, ("",))[0] in self._wanted)}  # fmt: skip
        if short:
            per = ", ".join(f"{channels.get(cid, (f'channel {cid}',))[0]} {n:,}" for cid, n in sorted(short.items()))
            self.lost = (f"{self.name} is damaged ({self.why or 'unreadable index'}): read {count:,} messages to the "
                         f"end of the file, but its statistics count {sum(short.values()):,} more ({per}): bytes were "
                         "cut out of it (a whole chunk), and those messages are lost")  # fmt: skip
