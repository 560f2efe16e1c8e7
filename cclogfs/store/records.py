"""Reading records back: the one place that reads and checks the record at an offset.

Physical framing apart from meaning, as LevelDB's log_reader: `read_record` checks the
framing (magic, lengths against the limits, header CRC32C, payload XXH3) and nothing
else; `records` walks a segment's records in log order on top of it and adds what the
log means (sequence continuity, field checks). Scan, reads through the index, recovery's
count of intact records past damage, compaction and fsck all go through these two.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

from .format import (
    AGED_META_KEY,
    RECORD_FIXED_SIZE,
    RECORD_MAGIC,
    Reason,
    RecordError,
    RecordFlag,
    RecordHeader,
    check_fields,
    check_fixed,
    check_payload,
    parse_header,
)
from .fs import FileSystem


class Source(Protocol):
    """Bytes of one file, read at an offset (short at the end of the file)."""

    def read(self, offset: int, n: int) -> bytes: ...


class ChunkReader:
    """Reads a file through a large buffer: one pread serves many small records."""

    CHUNK = 4 << 20

    def __init__(self, fs: FileSystem, fd: int):
        self.fs, self.fd = fs, fd
        self.buf, self.buf_pos = b"", 0

    def read(self, offset: int, n: int) -> bytes:
        start = offset - self.buf_pos
        if start < 0 or start + n > len(self.buf):
            if n > self.CHUNK:  # a big payload: read it alone
                return self.fs.pread(self.fd, n, offset)
            self.buf, self.buf_pos, start = self.fs.pread(self.fd, self.CHUNK, offset), offset, 0
        return self.buf[start : start + n]


class BytesAt:
    """Bytes already read, addressed by their offset in the file they came from."""

    def __init__(self, data: bytes, base: int = 0):
        self.data, self.base = data, base

    def read(self, offset: int, n: int) -> bytes:
        start = offset - self.base
        return self.data[start : start + n]


def read_record(source: Source, offset: int, available: int) -> tuple[RecordHeader, bytes]:
    """Header and payload of the physical record at `offset`, its framing and both checksums
    verified; `available` is how many bytes the file holds from `offset`. Raises
    RecordError (with `offset` set) naming the reason."""
    try:
        header_len = check_fixed(source.read(offset, RECORD_FIXED_SIZE), available)
        header = parse_header(source.read(offset, header_len))
        payload = source.read(offset + header_len, header.enc_len)
        check_payload(header, payload)
    except RecordError as err:
        err.offset = offset
        raise
    return header, payload


@dataclass(slots=True)
class Record:
    """One record of a segment in log order: where it is, what it says, whether to skip it."""

    offset: int
    header: RecordHeader
    payload: bytes
    skip: str | None  # a Reason for an intact record of another kind, version or flags

    @property
    def end(self) -> int:
        return self.offset + self.header.record_len


_PART = int(RecordFlag.PART)


def records(source: Source, start: int, size: int, first_seq: int) -> Iterator[Record]:
    """Every record from `start` to `size` in log order, each fully checked (framing,
    checksums, sequence continuity from `first_seq`, fields, and that each part of a split
    window is followed by its continuation). Stops by raising RecordError (with `offset`
    set) at the first record that fails.

    A record flagged PART is yielded before its continuation is seen: when the put it
    belongs to turns out unfinished (the next record is not its continuation, fails a
    check, or the range ends), the error is an `UnfinishedPut` whose `offset` is the put's
    first part, so that a caller drops what it took from the put's parts."""
    pos, seq = start, first_seq
    put: tuple[int, int] | None = None  # (offset, seq) of the first part of a put not finished yet
    last: RecordHeader | None = None  # the record before, while `put` is open
    while pos < size:
        try:
            header, payload = read_record(source, pos, size - pos)
            if header.seq != seq:
                raise RecordError(Reason.SEQ_GAP, f"seq {header.seq}, expected {seq}")
            skip = check_fields(header)
            if put is not None and (why := not_continued(last, header, skip)):
                raise UnfinishedPut(put, (pos, seq), why)
        except UnfinishedPut:
            raise
        except RecordError as err:
            err.offset = pos
            if put is not None:  # the put's last part is not there: it ends here unfinished
                raise UnfinishedPut(put, (pos, seq), f"then seq {seq}: {err}", cause=err) from err
            raise
        yield Record(pos, header, payload, skip)
        if skip is None and header.flags & _PART:
            put, last = put or (pos, seq), header
        else:
            put = last = None
        pos += header.record_len
        seq += 1
    if put is not None:
        raise UnfinishedPut(put, (pos, seq), "the range ends before its last part")


class UnfinishedPut(RecordError):
    """A split window whose last part is not there (FORMAT.md, "Splitting"): `offset` and
    `seqs[0]` are its first part's, `end` the (offset, seq) one past its last part found
    (where the next record starts, or the range ends), `cause` the failure there, if any."""

    def __init__(self, first: tuple[int, int], end: tuple[int, int], why: str, cause: RecordError | None = None):
        super().__init__(Reason.UNFINISHED_PUT, f"seqs {first[1]}..{end[1] - 1} are parts of a split window "
                                                f"whose last part is missing ({why})", first[0])  # fmt: skip
        self.first, self.end, self.cause = first, end, cause


def not_continued(last: RecordHeader, header: RecordHeader, skip: str | None) -> str | None:
    """Why `header` (the record after `last`, which is flagged PART) is not the next part of
    its window, or None: a part carries on the same stream, from where the part before
    ended, with the same meta (the key `aged` apart: compaction ages each part alone)."""
    if skip is not None:
        return f"a record this reader skips ({skip})"
    if header.name != last.name:
        return f"a window of {header.name!r}, not {last.name!r}"
    if header.start_ns < last.end_ns:
        return f"it starts at {header.start_ns} ns, before the part before ends ({last.end_ns} ns)"
    if header.meta != last.meta and _meta_apart_from_aged(header.meta) != _meta_apart_from_aged(last.meta):
        return "its meta differs"
    return None


def _meta_apart_from_aged(meta: bytes) -> object:
    try:
        value = json.loads(meta)
    except (ValueError, RecursionError):
        return meta
    if isinstance(value, dict):
        value.pop(AGED_META_KEY, None)
    return value


# The magic search reads this much at a time: with one record (at most the limits of
# FORMAT.md) and ChunkReader's buffer, it is all a search holds, whatever the file's size.
SEARCH_CHUNK = 1 << 20


def intact_in(fs: FileSystem, fd: int, start: int, end: int) -> Iterator[tuple[int, RecordHeader, bytes]]:
    """(offset, header, payload) of every intact record (framing and checksums hold) of the
    file between `start` and `end`, found by their magic. Streamed: memory stays within
    SEARCH_CHUNK + ChunkReader.CHUNK + one record, and holes (a sparse tail) are skipped,
    since zero bytes hold no record (FORMAT.md, "Bounded reads")."""
    source = ChunkReader(fs, fd)
    magic = len(RECORD_MAGIC)
    pos, buf, base = start, b"", start
    while pos < end:
        i = buf.find(RECORD_MAGIC, pos - base) if pos >= base else -1
        if i < 0:
            # A magic may straddle two chunks: go on from the last bytes of this one.
            pos = fs.next_data(fd, max(pos, base + len(buf) - magic + 1))
            if pos >= end:
                return
            buf, base = fs.pread(fd, min(SEARCH_CHUNK, end - pos), pos), pos
            if len(buf) < magic:
                return
            continue
        at = base + i
        try:
            header, payload = read_record(source, at, end - at)
        except RecordError:
            pos = at + 1
            continue
        yield at, header, payload
        pos = at + header.record_len


def count_intact_in(fs: FileSystem, fd: int, start: int, end: int) -> int:
    """How many intact records lie in the file between `start` and `end` (streamed)."""
    return sum(1 for _ in intact_in(fs, fd, start, end))
