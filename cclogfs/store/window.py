"""What the store hands out: a `Window` (the read handle a query returns) and a `Receipt`."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from ..codecs import codec_for_record, codec_numeric_id
from ..errors import CodecError, CorruptionError, StoreError, UnknownCodecError
from . import format, planted
from .format import AGED_META_KEY, Reason, RecordFlag, RecordHeader, check_fields
from .records import not_continued
from .segment import Segment


# How to read a record an older version wrote over the decode limit (FORMAT.md, "Limits"):
# the command line says it with its own words (cclogfs.cli replaces this text).
RAISE_DECODE_LIMIT = "raise cclogfs.store.format.DECODE_RAW_LIMIT (at most 256 MiB) before opening the store"


_PART = int(RecordFlag.PART)


@dataclass(frozen=True)
class Receipt:
    """What `put_window` stored. Durable once a later `sync()` (or group commit) completes."""

    seq: int
    name: str
    start_ns: int
    end_ns: int
    count: int
    raw_bytes: int
    stored_bytes: int
    records: int = 1  # a window over MAX_RECORD_RAW is stored as this many records, seq on (FORMAT.md)


class Window:
    """One stored window, as a query returns it. Reads its record on first use
    (`record`: header and payload already read and checked, as compaction has them)."""

    __slots__ = ("name", "seq", "start_ns", "end_ns", "count", "_segment", "_offset",
                 "_length", "_record")  # fmt: skip

    def __init__(self, name: str, seq: int, start_ns: int, end_ns: int, count: int,
                 segment: Segment, offset: int, length: int,
                 record: tuple[RecordHeader, bytes] | None = None):  # fmt: skip
        self.name, self.seq, self.start_ns, self.end_ns, self.count = name, seq, start_ns, end_ns, count
        self._segment, self._offset, self._length = segment, offset, length
        self._record = record

    def _read(self) -> tuple[RecordHeader, bytes]:
        if self._record is None:
            with self._segment.lock:  # the group-commit thread may be flushing this segment
                if self._segment.fd < 0:
                    raise StoreError(f"{self._segment.path} is closed: the store was closed, or compaction "
                                     "replaced or dropped this segment; query again")  # fmt: skip
                header, payload = self._segment.read_record(self._offset, self._length)
                self._check_entry(header)
                if header.flags & _PART and self._segment.sealed_size >= 0:
                    self._check_continued(header)
                self._record = header, payload
        return self._record

    def _check_entry(self, header: RecordHeader) -> None:
        """The record must be the one the index entry describes: a stale or forged index
        whose checksum holds would otherwise hand out another window's messages."""
        if "trust-index" in planted.BUGS:
            return
        said = (self.name, self.seq, self.start_ns, self.end_ns, self.count)
        found = (header.name, header.seq, header.start_ns, header.end_ns, header.count)
        if said != found:
            if self._segment.sealed_size >= 0:
                self._segment.distrust_index()
            raise CorruptionError(
                f"{self._segment.path}: record at offset {self._offset} is seq {header.seq} of "
                f"{header.name!r}, but the time index says seq {self.seq} of {self.name!r}; the index "
                "is rebuilt from the segment: query again",
                path=self._segment.path, offset=self._offset, reason=Reason.INDEX_MISMATCH,
            )  # fmt: skip

    def _check_continued(self, header: RecordHeader) -> None:
        """A part of a split window must be followed by its continuation. A sealed segment's
        index is trusted, so no scan saw the record after this one: a PART flag whose header
        CRC holds (forged, or a bug's) on a record nothing continues would hand out part of a
        window as if whole, with exit 0. One more header read, for parts only."""
        at, seg = self._offset + self._length, self._segment
        after = seg.read_header(at) if at < seg.size else None
        if at >= seg.size:
            why = f"it is the last record of the segment (seqs {seg.first_seq}..{seg.next_seq - 1})"
        elif after is None:
            why = f"the record after it (offset {at}) does not frame or fails its header CRC"
        elif after.seq != header.seq + 1:
            why = f"the record after it is seq {after.seq}"
        else:
            try:
                why = not_continued(header, after, check_fields(after))
            except format.RecordError as err:
                why = f"the record after it is damaged ({err})"
        if why is not None:
            raise CorruptionError(
                f"{seg.path}: record at offset {self._offset} (seq {header.seq} of {header.name!r}) is flagged "
                f"PART (its window goes on in the next record), but {why}: the window is incomplete",
                path=seg.path, offset=self._offset, reason=Reason.UNFINISHED_PUT,
            )  # fmt: skip

    def check(self) -> None:
        """Read and check the record now (framing, checksums, its index entry); raises
        CorruptionError naming the file, offset and reason. The record is kept for reading."""
        self._read()

    @property
    def offset(self) -> int:
        """Where the record starts in its segment file."""
        return self._offset

    @property
    def segment_path(self) -> str:
        """The segment file holding the record."""
        return self._segment.path

    def _json_field(self, field: str, raw: bytes) -> dict[str, Any]:
        """A record's meta or codec config: a JSON object. The header CRC holds, so anything
        else was written by another tool or forged: damage, named like any other."""
        try:
            value = json.loads(raw)
        except (ValueError, RecursionError):  # UnicodeDecodeError is a ValueError
            value = None
        if not isinstance(value, dict):
            raise CorruptionError(
                f"{self._segment.path}: record at offset {self._offset} (seq {self.seq}): its {field} is not "
                f"a JSON object ({bytes(raw[:40])!r})",
                path=self._segment.path, offset=self._offset, reason=Reason.BAD_FIELD,
            )  # fmt: skip
        return value

    @property
    def meta(self) -> dict[str, Any]:
        return self._json_field("meta", self._read()[0].meta)

    @property
    def codec_config(self) -> dict[str, Any]:
        return self._json_field("codec config", self._read()[0].config)

    @property
    def stored_bytes(self) -> int:
        return self._length

    @property
    def flags(self) -> int:
        """The record's flag bits (`cclogfs.store.RecordFlag`)."""
        return self._read()[0].flags

    @property
    def continues(self) -> bool:
        """Whether this record is a part of a split window that goes on in the next record
        (flag PART, FORMAT.md "Splitting"): the window is this record and those after it."""
        record = self._record
        if record is None:
            if self._over_decode_limit():
                return False  # never read here: messages() refuses it before reading it
            record = self._read()
        return record[0].flags & _PART != 0

    def _over_decode_limit(self) -> bool:
        """Whether the index entry's length is over what a read decodes (FORMAT.md, "Limits")."""
        return self._length > format.MAX_HEADER + format.DECODE_RAW_LIMIT + format.ENC_SLACK

    @property
    def aged(self) -> Any:
        """How the texts differ from what was put (meta key "aged"), or None when byte-exact."""
        header = self._read()[0]
        return self._json_field("meta", header.meta).get(AGED_META_KEY) if header.flags & RecordFlag.AGED else None

    def messages(self) -> Iterator[tuple[int, str]]:
        """(stamp_ns, JSON text) of each message, exactly as put."""
        # A read decodes at most DECODE_RAW_LIMIT of window (FORMAT.md, "Limits"): checked on
        # the index entry's length before the record is read, then on the header's raw_len.
        limit = format.DECODE_RAW_LIMIT
        if self._record is None and self._over_decode_limit():
            raise self._too_large(f"is {self._length} bytes long")
        header, payload = self._read()
        if header.raw_len > limit:
            raise self._too_large(f"holds a {header.raw_len}-byte window")
        self._json_field("codec config", header.config)
        try:
            codec = codec_for_record(header.config)
        except UnknownCodecError:
            raise  # intact, written by a newer cclogfs: not damage
        except CodecError as err:
            raise CorruptionError(f"{self._segment.path}: record at offset {self._offset} (seq {self.seq}): "
                                  f"its codec config cannot be used: {err}", path=self._segment.path,
                                  offset=self._offset, reason=Reason.BAD_FIELD) from None  # fmt: skip
        if codec_numeric_id(codec) != header.codec:
            raise CorruptionError(
                f"{self._segment.path}: record at offset {self._offset} names codec "
                f"{header.codec} in its header but {codec.codec_id!r} in its config",
                path=self._segment.path, offset=self._offset, reason=Reason.CODEC_MISMATCH,
            )  # fmt: skip
        if "trust-zstd-size" in planted.BUGS and codec.codec_id == "zstd":
            import zstandard  # the planted bug: a buffer of the size the frame declares

            zstandard.ZstdDecompressor().decompress(payload)
        stamps, texts = codec.decode(payload, count=header.count, raw_len=header.raw_len)
        self._check_utf8(texts)
        return zip(stamps, texts)

    def _too_large(self, what: str) -> CorruptionError:
        return CorruptionError(
            f"{self._segment.path}: record at offset {self._offset} (seq {self.seq}) {what}, over the "
            f"{format.DECODE_RAW_LIMIT}-byte limit of what a read decodes: forged, or written by an older "
            f"cclogfs; to read it, {RAISE_DECODE_LIMIT}",
            path=self._segment.path, offset=self._offset, reason=Reason.BAD_LENGTH,
        )  # fmt: skip

    def _check_utf8(self, texts: list[str]) -> None:
        """Codecs turn stray bytes into lone surrogates (they round-trip any bytes); the
        store only ever stores UTF-8, so such a text here is damage the checksums did not
        see, never a message to hand out. `isascii` is O(1): only other texts are encoded."""
        if all(map(str.isascii, texts)):  # most windows: one pass at C speed
            return
        for i, text in enumerate(texts):
            if not text.isascii():
                try:
                    text.encode("utf-8")
                except UnicodeEncodeError:
                    raise CodecError(
                        f"{self._segment.path}: record at offset {self._offset}: message {i} is not valid UTF-8"
                    ) from None

    def __repr__(self) -> str:
        return f"Window({self.name!r}, seq={self.seq}, {self.start_ns}..{self.end_ns}, count={self.count})"
