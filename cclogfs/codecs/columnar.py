"""The columnar codec: messages of one shape become one template plus typed columns.

Texts that share their literal text (keys, punctuation, whitespace, and the values that
never change in the window; see `shapes`) form a group: the literals are stored once and
each value slot becomes a column (`columns`), whose kind is kept only if rendering gives
every token back (else the tokens are stored verbatim). Texts without a shape are stored
verbatim in the same payload. The body is compressed with one zstd
frame; an xxh32 of the frame in the header makes any flipped byte an error, not a text.
The payload layout is specified in docs/CODEC_COLUMNAR.md.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np
import xxhash
import zstandard

from ..errors import CodecError
from .base import UTF8_ERRORS, Codec, encode_texts, utf8_size
from .columnar_format import (
    BODY_FACTOR,
    BODY_SLACK,
    FORMAT_VERSIONS,
    GROUP_HEADER,
    HEADER,
    LATEST_VERSION,
    MAX_GROUPS,
    RAW_GROUP,
    U32,
    VERSION_KINDS,
    ColumnKind,
)
from .columns import (
    Reader,
    _read_blob,
    _shuffle,
    _undo_zigzag_delta,
    _unshuffle,
    _utf8,
    _write_blob,
    _zigzag_delta,
    classify,
    float_deltas,
    quaternion_prediction,
    read_column,
    read_packed,
    slot_floats,
    write_column,
    write_packed,
)
from .shapes import ShapeMatcher
from .simple import read_zstd

__all__ = ["ColumnarCodec"]

# A float slot after three float slots is coded as a quaternion's w when at least this
# share of its rows has x^2 + y^2 + z^2 + w^2 within 1e-6 of 1.
_QUATERNION_SHARE = 0.9
# A string slot with at most this many distinct values splits its group (see _split_by_label).
_MAX_LABELS = 8


def _split_by_label(
    literals: tuple[str, ...], indices: list[int], rows: list[tuple[str, ...]]
) -> list[tuple[tuple[str, ...], list[int], list[tuple[str, ...]]]]:
    """Split a group by its first string slot with a few values (a frame id, say).

    /tf interleaves transforms of different frames; apart, each frame's values form a
    smooth series that delta coding shrinks, together they alternate and do not.
    """
    if len(rows) < 2 * _MAX_LABELS:
        return [(literals, indices, rows)]
    for j, token in enumerate(rows[0]):
        if token[:1] != '"':
            continue
        labels = {row[j] for row in rows}
        if 1 < len(labels) <= _MAX_LABELS:
            parts: dict[str, tuple[list[int], list]] = {}
            for i, row in zip(indices, rows):
                part = parts.setdefault(row[j], ([], []))
                part[0].append(i)
                part[1].append(row)
            return [(literals, idx, part_rows) for idx, part_rows in parts.values()]
    return [(literals, indices, rows)]


def _maybe_unit(xyz: list, w: np.ndarray) -> bool:
    """Whether the first or middle row of x, y, z, w is near unit: a cheap filter.

    A quaternion column has at least 90% unit rows, so it all but always passes; most
    float columns fail here without the numpy work of the full test.
    """
    for row in (0, len(w) // 2):
        try:
            parts = [float(e[row] if isinstance(e, np.ndarray) else e) for e in xyz]
        except (TypeError, ValueError):
            return False
        parts.append(float(w[row]))
        if abs(sum(c * c for c in parts) - 1.0) < 1e-6:  # c * c overflows to inf, not an error
            return True
    return False


def _encode_group(literals: tuple[str, ...], rows: list[tuple[str, ...]], version: int) -> bytes:
    """One group: header, literals, kinds, then each column's data."""
    n = len(rows)
    kinds, values = [], []
    floats: list[np.ndarray | str | None] = []  # what slot_floats takes, per slot
    for tokens in zip(*rows):
        kind, vals = classify(tokens, decimal=version >= 4)
        fl = vals if kind in (ColumnKind.FLOAT, ColumnKind.CONST) else None
        if kind is ColumnKind.FLOAT and len(floats) >= 3 and _maybe_unit(floats[-3:], vals):
            xyz = [slot_floats(f, n) for f in floats[-3:]]
            if all(f is not None for f in xyz):
                x, y, z = xyz
                with np.errstate(all="ignore"):
                    near_unit = np.abs(x * x + y * y + z * z + vals * vals - 1.0) < 1e-6
                if near_unit.mean() >= _QUATERNION_SHARE:
                    kind = ColumnKind.QUAT_W
                    vals = vals.view("<u8") ^ quaternion_prediction(x, y, z).view("<u8")
        if kind is ColumnKind.FLOAT and version >= 3:
            kind = ColumnKind.FLOAT_DELTA
        elif kind is ColumnKind.INT and version >= 2:
            kind = ColumnKind.INT_OFFSET if version >= 3 else ColumnKind.INT_PACKED
        kinds.append(kind)
        values.append(vals)
        floats.append(fl)
    deltas = [j for j, kind in enumerate(kinds) if kind is ColumnKind.FLOAT_DELTA]
    if deltas:
        orders, planes = float_deltas(np.stack([values[j] for j in deltas]).view("<i8"))
        for j, order, data in zip(deltas, orders, planes):
            values[j] = (order, data)
    out = bytearray(GROUP_HEADER.pack(n, len(kinds)))
    _write_blob([lit.encode() for lit in literals], [len(lit) for lit in literals], out)
    out += bytes(kinds)
    for kind, vals in zip(kinds, values):
        write_column(kind, vals, out)
    return bytes(out)


def _decode_group(reader: Reader, n: int, budget: int, version: int) -> list[str]:
    """The texts of one group; `budget` bounds the characters they may add up to."""
    count, slots = GROUP_HEADER.unpack(reader.take(GROUP_HEADER.size, "group header"))
    if count != n:
        raise CodecError(f"columnar payload is corrupt: a group holds {count} messages, ids say {n}")
    if 5 * slots > len(reader.view) - reader.pos:  # each slot needs a literal length and a kind
        raise CodecError(f"columnar payload is corrupt: a group claims {slots} value slots")
    counts, blob = _read_blob(reader, slots + 1, "literals")
    text = _utf8(blob, "literals")
    if int(counts.sum(dtype=np.uint64)) != len(text):
        raise CodecError("columnar payload is corrupt: literal lengths do not add up")
    ends = np.cumsum(counts, dtype=np.int64).tolist()
    literals = [text[a:b] for a, b in zip([0] + ends[:-1], ends)]
    kinds = reader.take(slots, "column kinds").tolist()
    if not VERSION_KINDS[version].issuperset(kinds):
        raise CodecError(f"columnar payload is corrupt: a column kind is not one of format version {version}")
    pieces = [literals[0].replace("%", "%%")]
    plain = [literals[0]]  # the template text, for groups where no slot varies
    static, varying = len(text), []
    varying_chars = 0
    floats: list[np.ndarray | str | None] = []
    for kind, literal in zip(kinds, literals[1:]):
        rendered, fl = read_column(kind, reader, n, floats)
        floats.append(rendered if isinstance(rendered, str) else fl)
        if isinstance(rendered, str):
            pieces.append(rendered.replace("%", "%%"))
            plain.append(rendered)
            static += len(rendered)
        else:
            pieces.append("%s")
            varying.append(rendered)
            varying_chars += sum(map(len, rendered))
        pieces.append(literal.replace("%", "%%"))
        plain.append(literal)
        # After every column, before anything is joined: a few bytes of payload can render
        # long values (a zero-width integer column renders n 20-digit numbers), so what the
        # group would produce is held to the window size the header states.
        if static * n + varying_chars > budget:
            raise CodecError("columnar payload is corrupt: a group renders beyond the window size")
    if not varying:
        return ["".join(plain)] * n
    fmt = "".join(pieces)
    return [fmt % row for row in zip(*varying)]


# A surrogate code point: an escaped byte that is not UTF-8 (see base), or a stray one.
_SURROGATE = re.compile("[\ud800-\udfff]")


def _shapeable(texts: Sequence[str]) -> list[str | None]:
    """The texts the shape matcher may see: those with a surrogate are stored verbatim."""
    if "".join(texts).isascii():
        return list(texts)
    return [None if _SURROGATE.search(t) else t for t in texts]


class ColumnarCodec(Codec):
    """Template + typed columns per JSON shape, zstd over the body; byte-exact."""

    codec_id = "columnar"

    def __init__(self, version: int = LATEST_VERSION, level: int = 3):
        if version not in FORMAT_VERSIONS:
            raise CodecError(
                f"columnar codec version {version!r} is unknown; this build writes {FORMAT_VERSIONS}"
            )
        if not isinstance(level, int) or not -7 <= level <= 22:
            raise CodecError(f"columnar zstd level must be an integer in -7..22, got {level!r}")
        self.version = version
        self.level = level
        self._local = threading.local()

    def get_config(self) -> dict[str, Any]:
        return {"id": self.codec_id, "version": self.version, "level": self.level}

    def _state(self) -> tuple[zstandard.ZstdCompressor, zstandard.ZstdDecompressor, ShapeMatcher]:
        state = getattr(self._local, "state", None)
        if state is None:  # zstd contexts and the shape cache are not thread-safe
            state = (
                zstandard.ZstdCompressor(level=self.level),
                zstandard.ZstdDecompressor(),
                ShapeMatcher(),
            )
            self._local.state = state
        return state

    def encode(self, stamps: Sequence[int], texts: Sequence[str]) -> bytes:
        count = len(stamps)
        if len(texts) != count:
            raise CodecError(f"a window needs one stamp per text, got {count} and {len(texts)}")
        try:
            stamp_words = np.array(stamps, dtype="<i8")
        except OverflowError as err:
            raise CodecError("a window stamp does not fit in a signed 64-bit integer") from err
        compressor, _, matcher = self._state()
        groups, _ = matcher.group_window(_shapeable(texts))
        ids = np.full(count, RAW_GROUP, dtype="<u2")
        bodies = []
        parts = [part for literals, indices, rows in groups for part in _split_by_label(literals, indices, rows)]
        # No trial decode: a match rebuilds its text from the literals by construction,
        # and classify() keeps a column kind only if rendering it gives every token back.
        for literals, indices, rows in parts[:MAX_GROUPS]:
            if len(indices) == count:  # the usual window: one group holds every message
                ids.fill(len(bodies))
            else:
                ids[indices] = len(bodies)
            bodies.append(_encode_group(literals, rows, self.version))
        raw_indices = np.flatnonzero(ids == RAW_GROUP).tolist()
        body = bytearray(U32.pack(len(bodies)))
        body += ids.tobytes()
        if self.version == 1:
            body += _shuffle(_zigzag_delta(stamp_words, 1))
        else:
            write_packed(stamp_words, body, offset=self.version >= 3)
        for data in bodies:
            body += data
        raw_texts = encode_texts([texts[i] for i in raw_indices])
        _write_blob(raw_texts, [len(t) for t in raw_texts], body)
        raw_len = 4 + 12 * count + utf8_size(texts)
        if len(body) > BODY_FACTOR * raw_len + BODY_SLACK:  # pragma: no cover - cannot happen
            raise CodecError("columnar body would exceed its decoding bound")
        frame = compressor.compress(bytes(body))
        return HEADER.pack(self.version, len(body), xxhash.xxh32_intdigest(frame)) + frame

    def decode(self, data: bytes, *, count: int, raw_len: int) -> tuple[list[int], list[str]]:
        text_budget = raw_len - 4 - 12 * count
        if count < 0 or text_budget < 0:
            raise CodecError(f"a window of {count} messages cannot have a raw size of {raw_len}")
        if len(data) < HEADER.size:
            raise CodecError("columnar payload is shorter than its header")
        version, body_len, checksum = HEADER.unpack_from(data, 0)
        frame = memoryview(data)[HEADER.size :]
        if xxhash.xxh32_intdigest(frame) != checksum:
            raise CodecError("columnar payload fails its xxh32 checksum")
        if version not in FORMAT_VERSIONS:
            raise CodecError(f"columnar payload has format version {version}, not one of {FORMAT_VERSIONS}")
        if body_len > BODY_FACTOR * raw_len + BODY_SLACK:
            raise CodecError(f"columnar payload claims a {body_len}-byte body for a {raw_len}-byte window")
        body = self._decompress(frame, body_len)
        reader = Reader(body)
        n_groups = reader.u32("group count")
        if n_groups > min(count, MAX_GROUPS):
            raise CodecError(f"columnar payload is corrupt: {n_groups} groups for {count} messages")
        ids = reader.array("<u2", count, "group ids")
        valid = (ids < n_groups) | (ids == RAW_GROUP)
        if not valid.all():
            raise CodecError("columnar payload is corrupt: a message names a group that does not exist")
        if version == 1:
            words = _unshuffle(reader.array("u1", 8 * count, "stamps"), count)
            stamps = _undo_zigzag_delta(words, 1).tolist()
        else:
            stamps = read_packed(reader, count, "stamps", offset=version >= 3).tolist()
        order = np.argsort(ids, kind="stable")
        sizes = np.bincount(ids[ids != RAW_GROUP], minlength=n_groups).tolist()
        out: list[str] = [""] * count
        pos, total = 0, 0
        for g in range(n_groups):
            if sizes[g] == 0:
                raise CodecError(f"columnar payload is corrupt: group {g} has no messages")
            texts = _decode_group(reader, sizes[g], text_budget, version)
            total += utf8_size(texts)
            if sizes[g] == count:  # one group holds the whole window, in order
                out = texts
            else:
                for i, text in zip(order[pos : pos + sizes[g]].tolist(), texts):
                    out[i] = text
            if total > text_budget:
                raise CodecError("columnar payload renders more text than the window holds")
            pos += sizes[g]
        raw_positions = order[pos:].tolist()
        lengths, blob = _read_blob(reader, len(raw_positions), "raw texts")
        if int(lengths.sum(dtype=np.uint64)) != len(blob):
            raise CodecError("columnar payload is corrupt: raw text lengths do not add up")
        start = 0
        for i, length in zip(raw_positions, lengths.tolist()):
            out[i] = str(blob[start : start + length], "utf-8", UTF8_ERRORS)
            start += length
        total += len(blob)
        if reader.pos != len(body):
            raise CodecError("columnar payload is corrupt: bytes are left over after the last group")
        if total != text_budget:
            raise CodecError(
                f"columnar payload decodes to {total} bytes of text, the header says {text_budget}"
            )
        return stamps, out

    def _decompress(self, data: memoryview, body_len: int) -> bytes:
        return read_zstd(self._state()[1], data, body_len, "columnar payload")
