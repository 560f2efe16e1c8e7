"""A ROS 1 bag's messages read straight from its chunks, in the order rosbags gives them.

rosbags' `Reader.messages` reads every message record through a file object over the
decompressed chunk: a seek, the record header parsed into a dict through three small
reads, then the data. Once the message formatting got fast (jsontext.roswire), that was
a fifth of `record`'s time on a bag (issue 14). This loop reads the same records, found
through the same index (rosbags read it when the bag was opened), from the chunk's bytes,
and yields the same (connection, log time, bytes) tuples in the same order.

The order: rosbags merges the selected connections' indexes (each sorted by time) with
`heapq.merge`, and its index entries compare by time only, so ties keep the order of the
connections, then each index's own order. A stable sort of the indexes concatenated in
that order gives exactly that.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from itertools import chain
from operator import itemgetter
from typing import Any

from rosbags.rosbag1 import Reader as Bag1Reader
from rosbags.rosbag1.reader import IndexData

from ..errors import SourceError

_U32 = struct.Struct("<I").unpack_from
_TIME = struct.Struct("<II").unpack
_MSGDATA, _CONNECTION = b"\x02", b"\x07"  # record ops (the ROS 1 bag format, op field)
# A message record's header is three fields, `conn=`, `op=` and `time=`, in the order its
# writer chose: C++ rosbag writes conn, op, time; rosbags writes op, conn, time. Each
# layout is read with one struct call and its constant bytes compared; any other header
# takes the general parser (`_header`).
_ROSBAG_CPP = struct.Struct("<13sI8s9sIII").unpack_from  # ...conn=, conn, ...op=\x02, ...time=, sec, nsec, size
_CPP_CONST = (b"&\0\0\0\t\0\0\0conn=", b"\x04\0\0\0op=\x02", b"\r\0\0\0time=")
_ROSBAGS = struct.Struct("<12s9sI9sIII").unpack_from  # ...op=\x02, ...conn=, conn, ...time=, sec, nsec, size
_ROSBAGS_CONST = (b"&\0\0\0\x04\0\0\0op=\x02", b"\t\0\0\0conn=", b"\r\0\0\0time=")
_FIXED = 46  # bytes of either layout, the data size included
_INDEX_HEAD = 55  # an index data record's header (its length, four fields) and its data size
_INDEX_ENTRY = struct.Struct("<III")  # an index entry: the message's sec, nsec, offset in the chunk


class IndexedReader(Bag1Reader):
    """rosbags' ROS 1 reader, its index read faster: the same `indexes`, the same errors.

    Opening a bag, rosbags reads every index entry with three struct calls and a named
    tuple's Python-level `__new__`: 1.5 us per message, most of opening a bag (issue 14).
    Here a connection's entries in a chunk are read with one `iter_unpack` and the same
    `IndexData` tuples are built in C. The first record (from which rosbags learns the
    order of the header's fields) and any record that is not whole are read by rosbags'
    own `read_index_data`, from the same place: its checks and errors stay its own.
    """

    def read_index_data(self, pos: int, indexes: dict[int, list[Any]]) -> None:
        bio, offsets = self.bio, self.index_data_header_offsets
        start = bio.tell()
        if offsets is not None and len(head := bio.read(_INDEX_HEAD)) == _INDEX_HEAD:
            count, size = _U32(head, offsets[1])[0], _U32(head, _INDEX_HEAD - 4)[0]
            if size == count * _INDEX_ENTRY.size and len(data := bio.read(size)) == size:
                new = tuple.__new__
                indexes[_U32(head, offsets[0])[0]].extend(
                    [new(IndexData, (sec * 1_000_000_000 + nsec, pos, offset))
                     for sec, nsec, offset in _INDEX_ENTRY.iter_unpack(data)])  # fmt: skip
                return
        bio.seek(start)
        super().read_index_data(pos, indexes)


def messages(bag: Any, connections: Sequence[Any], name: str) -> Iterator[tuple[Any, int, bytes]]:
    """(connection, log time in ns, message bytes) of `connections` in rosbags' order.
    `bag` is an open `rosbags.rosbag1.Reader`; `name` the file, for errors."""
    by_id = {c.id: c for c in bag.connections}
    entries = sorted(chain.from_iterable(bag.indexes[c.id] for c in connections), key=itemgetter(0))
    chunk_pos, data = -1, b""
    for time, pos, offset in entries:
        if pos != chunk_pos:
            data, chunk_pos = _chunk(bag, pos, name), pos
        if offset + _FIXED <= len(data):
            a, conn, b, c, sec, nsec, size = _ROSBAG_CPP(data, offset)
            if (a, b, c) != _CPP_CONST:
                a, b, conn, c, sec, nsec, size = _ROSBAGS(data, offset)
                if (a, b, c) != _ROSBAGS_CONST:
                    size = -1
            start = offset + _FIXED
            if size >= 0 and start + size <= len(data) and sec * 1_000_000_000 + nsec == time and conn in by_id:
                yield by_id[conn], time, data[start : start + size]
                continue
        yield _general(data, offset, time, pos, by_id, name)


def _general(data: bytes, offset: int, time: int, pos: int, by_id: dict, name: str) -> tuple[Any, int, bytes]:
    """The message record at `offset` of a chunk, any header layout, as rosbags reads it."""
    while True:  # connection records may sit before a message, as rosbags allows
        fields, offset = _header(data, offset, name, pos)
        if fields.get(b"op") != _CONNECTION:
            break
        offset += 4 + _U32(data, offset)[0]
    size = _U32(data, offset)[0] if offset + 4 <= len(data) else -1
    start = offset + 4
    if fields.get(b"op") != _MSGDATA or size < 0 or start + size > len(data):
        raise SourceError(f"{name}: the chunk at byte {pos:,} holds no whole message record at offset {offset:,} "
                          f"where the bag's index puts one")  # fmt: skip
    conn, stamp = fields.get(b"conn", b""), fields.get(b"time", b"")
    if len(conn) != 4 or len(stamp) != 8 or (t := _TIME(stamp))[0] * 1_000_000_000 + t[1] != time:
        raise SourceError(f"{name}: the message record at offset {offset:,} of the chunk at byte {pos:,} "
                          f"does not match the bag's index (connection or time)")  # fmt: skip
    if (con := by_id.get(_U32(conn)[0])) is None:
        raise SourceError(f"{name}: the message record at offset {offset:,} of the chunk at byte {pos:,} names "
                          f"connection {_U32(conn)[0]}, which the bag does not have")  # fmt: skip
    return con, time, data[start : start + size]


def _chunk(bag: Any, pos: int, name: str) -> bytes:
    """The decompressed bytes of the chunk at `pos`."""
    chunk = bag.chunks[pos]
    bag.bio.seek(chunk.datapos)
    raw = bag.bio.read(chunk.datasize)
    if len(raw) != chunk.datasize:
        raise SourceError(f"{name}: the chunk at byte {pos:,} is cut short ({len(raw):,} of {chunk.datasize:,} bytes)")
    return chunk.decompressor(raw)


def _header(data: bytes, offset: int, name: str, pos: int) -> tuple[dict[bytes, bytes], int]:
    """A record header's fields (`name=value`, each after its uint32 length) and the
    offset after the header."""
    end = offset + 4 + (_U32(data, offset)[0] if offset + 4 <= len(data) else len(data))
    if end > len(data):
        raise SourceError(f"{name}: the record header at offset {offset:,} of the chunk at byte {pos:,} is cut short")
    fields = {}
    at = offset + 4
    while at < end:
        size = _U32(data, at)[0] if at + 4 <= end else end
        at += 4
        key, sep, value = data[at : at + size].partition(b"=")
        if not sep or at + size > end:
            raise SourceError(f"{name}: a field of the record header at offset {offset:,} of the chunk at byte "
                              f"{pos:,} cannot be parsed")  # fmt: skip
        fields[key] = value
        at += size
    return fields, end
