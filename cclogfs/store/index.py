"""The time index of one segment: which records of which stream cover which times.

Entries of a stream are sorted by (start, seq). With the running maximum of `end` (derived
on load, never stored), "records overlapping [t0, t1]" is two binary searches and a scan of
only the candidates between them, whatever the size of the segment.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Iterable
from typing import Any
from dataclasses import dataclass

import numpy as np

from .format import (
    FILE_VERSION,
    INDEX_ENTRY_FIELDS,
    INDEX_HEADER,
    INDEX_MAGIC,
    MAX_NAME,
    Reason,
    RecordError,
    xxh3,
)

ENTRY = np.dtype(INDEX_ENTRY_FIELDS)


def overlap_slice(starts: np.ndarray, run_max_end: np.ndarray, t0: int, t1: int) -> slice:
    """Candidates overlapping [t0, t1] among items sorted by start (a superset: filter by end)."""
    hi = int(np.searchsorted(starts, t1, side="right"))
    lo = int(np.searchsorted(run_max_end, t0, side="left"))
    return slice(lo, max(lo, hi))


@dataclass
class StreamEntries:
    """The entries of one stream in one segment, sorted by (start, seq)."""

    entries: np.ndarray
    run_max_end: np.ndarray

    def overlapping(self, t0: int, t1: int) -> np.ndarray:
        cand = self.entries[overlap_slice(self.entries["start"], self.run_max_end, t0, t1)]
        return cand[cand["end"] >= t0]


class SegmentIndex:
    """Index of one segment: stream names and their sorted entries."""

    def __init__(self, names: list[str], entries: np.ndarray):
        self.names = names
        order = np.lexsort((entries["seq"], entries["start"], entries["stream"]))
        self.entries = entries[order]
        self.streams: dict[str, StreamEntries] = {}
        bounds = np.searchsorted(self.entries["stream"], np.arange(len(names) + 1))
        for i, name in enumerate(names):
            part = self.entries[bounds[i] : bounds[i + 1]]
            if len(part):
                self.streams[name] = StreamEntries(part, np.maximum.accumulate(part["end"]))

    @classmethod
    def build(cls, rows: Iterable[tuple[str, int, int, int, int, int, int, int]]) -> SegmentIndex:
        """From (name, count, seq, start, end, offset, length, raw_len) rows in any order."""
        ids: dict[str, int] = {}
        table = [(ids.setdefault(r[0], len(ids)), *r[1:]) for r in rows]
        return cls(list(ids), np.array(table, dtype=ENTRY) if table else np.zeros(0, ENTRY))

    def __len__(self) -> int:
        return len(self.entries)

    def rows(self) -> list[tuple[str, int, int, int, int, int, int, int]]:
        """The (name, count, seq, start, end, offset, length, raw_len) rows it was built from,
        in log (offset) order."""
        names = self.names
        out = [(names[e[0]], *e[1:]) for e in self.entries.tolist()]
        out.sort(key=lambda r: r[5])
        return out

    def encode(self, first_seq: int, segment_size: int) -> bytes:
        names = json.dumps(self.names).encode()
        head = INDEX_HEADER.pack(
            INDEX_MAGIC, FILE_VERSION, 0, first_seq, segment_size, len(self.entries), len(names)
        )
        body = head + names + self.entries.astype(ENTRY).tobytes()
        return body + struct.pack("<Q", xxh3(body))

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
        expect = INDEX_HEADER.size + names_len + count * ENTRY.itemsize + 8
        if len(data) != expect or names_len > count * (MAX_NAME * 6 + 4) + 2:
            raise RecordError(Reason.BAD_LENGTH, f"index is {len(data)} bytes, expected {expect}")
        (digest,) = struct.unpack_from("<Q", data, len(data) - 8)
        if digest != xxh3(memoryview(data)[:-8]):
            raise RecordError(Reason.PAYLOAD_HASH, "index checksum")
        if seq != first_seq or size != segment_size:
            raise RecordError(Reason.INDEX_MISMATCH, "index describes another version of the segment")
        pos = INDEX_HEADER.size
        names = json.loads(data[pos : pos + names_len])
        entries = np.frombuffer(data, ENTRY, count, pos + names_len).copy()
        if len(entries) and int(entries["stream"].max()) >= len(names):
            raise RecordError(Reason.BAD_FIELD, "index entry names an unknown stream")
        return cls(names, entries)

    def stream_stats(self) -> dict[str, dict[str, int]]:
        """Per stream: windows, messages, start_ns, end_ns, raw_bytes, stored_bytes."""
        out = {}
        for name, s in self.streams.items():
            e = s.entries
            out[name] = {
                "windows": len(e),
                "messages": int(e["count"].sum()),
                "start_ns": int(e["start"].min()),
                "end_ns": int(e["end"].max()),
                "raw_bytes": int(e["raw_len"].sum()),
                "stored_bytes": int(e["length"].sum()),
            }
        return out


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
        self._streams: dict[str, tuple[np.ndarray, np.ndarray, list[Any]]] = {}
        for stream, spans in by_stream.items():
            spans.sort(key=lambda x: (x[0], x[2]))
            starts = np.array([x[0] for x in spans], dtype=np.int64)
            run_max = np.maximum.accumulate(np.array([x[1] for x in spans], dtype=np.int64))
            self._streams[stream] = (starts, run_max, [x[3] for x in spans])

    def overlapping(self, name: str, t0: int, t1: int) -> list[Any]:
        """Segments whose span of stream `name` may overlap [t0, t1] (a superset), by start."""
        found = self._streams.get(name)
        if found is None:
            return []
        starts, run_max, segs = found
        return segs[overlap_slice(starts, run_max, t0, t1)]
