"""The time index of one segment: which records of which stream cover which times.

Entries of a stream are sorted by (start, seq). With the running maximum of `end` (derived
on load, never stored), "records overlapping [t0, t1]" is two binary searches and a scan of
only the candidates between them, whatever the size of the segment.

Plain Python (struct, bisect), no numpy: a reader that asks for one second of a store
loads one or two indexes, and importing numpy would cost it more than everything else.
"""

from __future__ import annotations

import json
import struct
from bisect import bisect_left, bisect_right
from collections.abc import Iterable, Sequence
from functools import cached_property
from itertools import accumulate, groupby
from operator import itemgetter
from typing import Any

from .format import (
    FILE_VERSION,
    INDEX_ENTRY,
    INDEX_HEADER,
    INDEX_MAGIC,
    MIN_RECORD,
    SEGMENT_HEADER_SIZE,
    CHECKSUMS_OFF,
    Reason,
    RecordError,
    index_size_limit,
    xxh3,
)
from .fs import FileSystem, FileTooLargeError

Row = tuple[str, int, int, int, int, int, int, int]  # (name, count, seq, start, end, offset, length, raw_len)
# One record in the index (FORMAT.md, "Time index"): (stream, count, seq, start, end,
# offset, length, raw_len), `stream` indexing the names. Plain tuples, as struct gives
# them: a named tuple per entry made loading an index of 5,000 entries 15 times slower.
Entry = tuple[int, int, int, int, int, int, int, int]
STREAM, COUNT, SEQ, START, END, OFFSET, LENGTH, RAW_LEN = range(8)

_ORDER = itemgetter(STREAM, START, SEQ)


def overlap_slice(starts: Sequence[int], run_max_end: Sequence[int], t0: int, t1: int) -> slice:
    """Candidates overlapping [t0, t1] among items sorted by start (a superset: filter by end)."""
    hi = bisect_right(starts, t1)
    lo = bisect_left(run_max_end, t0)
    return slice(lo, max(lo, hi))


class StreamEntries:
    """The entries of one stream in one segment, sorted by (start, seq)."""

    def __init__(self, entries: list[Entry]):
        self.entries = entries

    @cached_property
    def _search(self) -> tuple[list[int], list[int]]:
        """Starts and the running maximum of ends, built on the first query only."""
        return list(map(itemgetter(START), self.entries)), list(accumulate(map(itemgetter(END), self.entries), max))

    @property
    def run_max_end(self) -> list[int]:
        return self._search[1]

    def overlapping(self, t0: int, t1: int) -> list[Entry]:
        starts, run_max_end = self._search
        return [e for e in self.entries[overlap_slice(starts, run_max_end, t0, t1)] if e[END] >= t0]


class SegmentIndex:
    """Index of one segment: stream names and their sorted entries."""

    def __init__(self, names: list[str], entries: Iterable[Entry]):
        self.names = names
        self.entries = sorted(entries, key=_ORDER)
        self.streams: dict[str, StreamEntries] = {
            names[stream]: StreamEntries(list(part)) for stream, part in groupby(self.entries, itemgetter(STREAM))
        }

    @classmethod
    def build(cls, rows: Iterable[Row]) -> SegmentIndex:
        """From (name, count, seq, start, end, offset, length, raw_len) rows in any order."""
        ids: dict[str, int] = {}
        entries = [(ids.setdefault(r[0], len(ids)), *r[1:]) for r in rows]
        return cls(list(ids), entries)

    def __len__(self) -> int:
        return len(self.entries)

    def rows(self) -> list[Row]:
        """The rows it was built from, in log (offset) order."""
        names = self.names
        return [(names[stream], count, seq, start, end, offset, length, raw_len)
                for stream, count, seq, start, end, offset, length, raw_len
                in sorted(self.entries, key=itemgetter(OFFSET))]  # fmt: skip

    def tiles(self, first_seq: int, next_seq: int, start: int, end: int) -> bool:
        """Whether the entries hold every seq from `first_seq` to `next_seq` (exclusive), once,
        in records that follow one another from byte `start` to byte `end` without a gap or
        an overlap."""
        pos, seq = start, first_seq
        for e in sorted(self.entries, key=itemgetter(OFFSET)):  # the entries themselves: no new tuples
            if e[OFFSET] != pos or e[SEQ] != seq:
                return False
            pos, seq = pos + e[LENGTH], seq + 1
        return (pos, seq) == (end, next_seq)

    def encoded_size(self) -> int:
        """Bytes `encode` gives, without encoding it."""
        return INDEX_HEADER.size + len(json.dumps(self.names).encode()) + INDEX_ENTRY.size * len(self.entries) + 8

    def encode(self, first_seq: int, segment_size: int) -> bytes:
        names = json.dumps(self.names).encode()
        head = INDEX_HEADER.pack(
            INDEX_MAGIC, FILE_VERSION, 0, first_seq, segment_size, len(self.entries), len(names)
        )
        body = b"".join([head, names, *(INDEX_ENTRY.pack(*e) for e in self.entries)])
        return body + struct.pack("<Q", xxh3(body))

    @classmethod
    def read(cls, fs: FileSystem, path: str, first_seq: int, segment_size: int) -> SegmentIndex:
        """Load the index file at `path` of the segment (first_seq, segment_size); its size is
        checked against the limit for that segment before it is read (raises RecordError,
        or OSError when it cannot be read)."""
        try:
            data = fs.read_file(path, limit=index_size_limit(segment_size))
        except FileTooLargeError as err:
            raise RecordError(Reason.BAD_LENGTH, err.strerror) from None
        return cls.decode(data, first_seq, segment_size)

    @classmethod
    def decode(cls, data: bytes, first_seq: int, segment_size: int) -> SegmentIndex:
        """Parse an index file, checking it describes this segment (raises RecordError)."""
        if len(data) < INDEX_HEADER.size + 8:
            raise RecordError(Reason.TORN, f"index of {len(data)} bytes")
        magic, version, _flags, seq, size, count, names_len = INDEX_HEADER.unpack_from(data)
        if magic != INDEX_MAGIC:
            raise RecordError(Reason.BAD_MAGIC, f"not an index: {magic!r}")
        if version != FILE_VERSION:
            raise RecordError(Reason.UNSUPPORTED_VERSION, f"index version {version}")
        expect = INDEX_HEADER.size + names_len + count * INDEX_ENTRY.size + 8
        if len(data) != expect or expect > index_size_limit(segment_size):
            raise RecordError(Reason.BAD_LENGTH, f"index is {len(data)} bytes, expected {expect}")
        (digest,) = struct.unpack_from("<Q", data, len(data) - 8)
        if digest != xxh3(memoryview(data)[:-8]) and "index" not in CHECKSUMS_OFF:
            raise RecordError(Reason.PAYLOAD_HASH, "index checksum")
        if seq != first_seq or size != segment_size:
            raise RecordError(Reason.INDEX_MISMATCH, "index describes another version of the segment")
        pos = INDEX_HEADER.size
        names = _names(data[pos : pos + names_len], count)
        entries = list(INDEX_ENTRY.iter_unpack(memoryview(data)[pos + names_len : -8]))
        _check_entries(entries, len(names), segment_size)
        return cls(names, entries)

    def stream_stats(self) -> dict[str, dict[str, int]]:
        """Per stream: windows, messages, start_ns, end_ns, raw_bytes, stored_bytes."""
        out = {}
        for name, s in self.streams.items():
            e = s.entries
            out[name] = {
                "windows": len(e),
                "messages": sum(map(itemgetter(COUNT), e)),
                "start_ns": min(map(itemgetter(START), e)),
                "end_ns": max(map(itemgetter(END), e)),
                "raw_bytes": sum(map(itemgetter(RAW_LEN), e)),
                "stored_bytes": sum(map(itemgetter(LENGTH), e)),
            }
        return out


def _names(raw: bytes, count: int) -> list[str]:
    """The index's stream names: a JSON list of distinct, non-empty strings."""
    try:
        names = json.loads(raw)
    except (ValueError, RecursionError):  # UnicodeDecodeError is a ValueError
        raise RecordError(Reason.BAD_FIELD, "index stream names are not JSON") from None
    if (not isinstance(names, list) or not all(isinstance(n, str) and n for n in names)
            or len(set(names)) != len(names) or len(names) > count):  # fmt: skip
        raise RecordError(Reason.BAD_FIELD, "index stream names are not a list of distinct names")
    return names


def _check_entries(entries: list[Entry], streams: int, segment_size: int) -> None:
    """Every entry names a known stream and a stretch of the segment a record can fill:
    reads trust offset and length to size what they read."""
    for e in entries:
        offset, length = e[OFFSET], e[LENGTH]
        if e[STREAM] >= streams:
            raise RecordError(Reason.BAD_FIELD, "index entry names an unknown stream")
        if (offset < SEGMENT_HEADER_SIZE or length < MIN_RECORD or length > segment_size
                or offset > segment_size - length or e[COUNT] < 1 or e[END] < e[START]):  # fmt: skip
            raise RecordError(Reason.BAD_FIELD, f"index entry of seq {e[SEQ]} (offset {offset}, "
                                                f"{length} bytes) lies outside its segment or is empty")  # fmt: skip


def merge_stream_stats(total: dict[str, dict[str, int]], stats: dict[str, dict[str, int]]) -> None:
    """Add one segment's `stream_stats()` (or a sum of them) into `total`, in place."""
    for name, st in stats.items():
        t = total.get(name)
        if t is None:
            total[name] = dict(st)
            continue
        for key in ("windows", "messages", "raw_bytes", "stored_bytes"):
            t[key] += st[key]
        t["start_ns"] = min(t["start_ns"], st["start_ns"])
        t["end_ns"] = max(t["end_ns"], st["end_ns"])


class SegmentSpans:
    """Across segments: which may hold windows of a stream within [t0, t1]. Built from each
    segment's per-stream statistics (start_ns, end_ns), searched like a segment's entries."""

    def __init__(self, items: Iterable[tuple[int, Any, dict[str, dict[str, int]]]]):
        """`items`: (first_seq, segment, stream_stats()) of each segment."""
        by_stream: dict[str, list[tuple[int, int, int, Any]]] = {}
        for first_seq, seg, streams in items:
            for stream, st in streams.items():
                by_stream.setdefault(stream, []).append((st["start_ns"], st["end_ns"], first_seq, seg))
        self._streams: dict[str, tuple[list[int], list[int], list[Any]]] = {}
        for stream, spans in by_stream.items():
            spans.sort(key=lambda x: (x[0], x[2]))
            starts = [x[0] for x in spans]
            run_max = list(accumulate((x[1] for x in spans), max))
            self._streams[stream] = (starts, run_max, [x[3] for x in spans])

    def overlapping(self, name: str, t0: int, t1: int) -> list[Any]:
        """Segments whose span of stream `name` may overlap [t0, t1] (a superset), by start."""
        found = self._streams.get(name)
        if found is None:
            return []
        starts, run_max, segs = found
        return segs[overlap_slice(starts, run_max, t0, t1)]
