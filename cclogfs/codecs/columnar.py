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

import threading
from collections.abc import Sequence
from typing import Any

import xxhash
import zstandard

from ..errors import CodecError
from .base import UTF8_ERRORS, Codec, utf8_size
from .columnar_format import (
    BODY_FACTOR,
    BODY_SLACK,
    FORMAT_VERSIONS,
    GROUP_HEADER,
    HEADER,
    LATEST_VERSION,
    MAX_GROUPS,
    RAW_GROUP,
    VERSION_KINDS,
)
from .columns_read import Reader, read_blob, read_column, read_packed, split, undo_zigzag_delta, utf8
from .shapes import ShapeMatcher
from .simple import read_zstd

__all__ = ["ColumnarCodec"]

# The compiled join (cclogfs/codecs/_rows.c, where setup.py could build it): the texts the
# % template below gives, 5-7x faster on the speed bench's odometry groups. Without it, or
# for texts wider than one byte a character, the template.
try:
    from ._rows import join_rows as _join_rows_c
except ImportError:
    _join_rows_c = None


def _decode_group(reader: Reader, n: int, budget: int, version: int) -> list[str]:
    """The texts of one group; `budget` bounds the characters they may add up to."""
    count, slots = GROUP_HEADER.unpack(reader.take(GROUP_HEADER.size, "group header"))
    if count != n:
        raise CodecError(f"columnar payload is corrupt: a group holds {count} messages, ids say {n}")
    if 5 * slots > len(reader.view) - reader.pos:  # each slot needs a literal length and a kind
        raise CodecError(f"columnar payload is corrupt: a group claims {slots} value slots")
    counts, blob = read_blob(reader, slots + 1, "literals")
    text = utf8(blob, "literals")
    literals = split(text, counts, "literal")
    kinds = reader.take(slots, "column kinds").tolist()
    if not VERSION_KINDS[version].issuperset(kinds):
        raise CodecError(f"columnar payload is corrupt: a column kind is not one of format version {version}")
    between = [[literals[0]]]  # the text before, between and after the varying columns
    static, varying = len(text), []
    varying_chars = 0
    floats: list[list[float] | str | None] = []
    for kind, literal in zip(kinds, literals[1:]):
        rendered, fl = read_column(kind, reader, n, floats)
        floats.append(rendered if isinstance(rendered, str) else fl)
        if isinstance(rendered, str):  # one token for every row: part of the text around
            between[-1].append(rendered)
            static += len(rendered)
        else:
            varying.append(rendered)
            varying_chars += sum(map(len, rendered))
            between.append([])
        between[-1].append(literal)
        # After every column, before anything is joined: a few bytes of payload can render
        # long values (a zero-width integer column renders n 20-digit numbers), so what the
        # group would produce is held to the window size the header states.
        if static * n + varying_chars > budget:
            raise CodecError("columnar payload is corrupt: a group renders beyond the window size")
    return join_rows(["".join(b) for b in between], varying, n)


def join_rows(literals: list[str], columns: list[list[str]], n: int) -> list[str]:
    """The n texts literals[0] + columns[0][i] + literals[1] + ... + literals[-1]."""
    if not columns:
        return literals * n
    if _join_rows_c is not None:
        rows = _join_rows_c(tuple(literals), tuple(columns))
        if rows is not NotImplemented:
            return rows
    fmt = "%s".join(literal.replace("%", "%%") for literal in literals)
    return [fmt % row for row in zip(*columns)]


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
        # Imported here: the encoder needs numpy, and a reader (`cclog cat`) should not
        # pay for importing it.
        from .columnar_encode import encode_window

        compressor, _, matcher = self._state()
        return encode_window(compressor, matcher, self.version, stamps, texts)

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
        ids = reader.ints("H", count, "group ids")
        sizes = [0] * n_groups
        for g in ids:
            if g < n_groups:
                sizes[g] += 1
            elif g != RAW_GROUP:
                raise CodecError("columnar payload is corrupt: a message names a group that does not exist")
        if version == 1:
            stamps = undo_zigzag_delta(reader.words(count, 8, "stamps"), 1)
        else:
            stamps = read_packed(reader, count, "stamps", offset=version >= 3)
        # Stable: by group, then position. Not needed (nor its count ints held) when one
        # group holds the whole window, as in most windows of one stream.
        whole = n_groups == 1 and sizes[0] == count
        order = [] if whole else sorted(range(count), key=ids.__getitem__)
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
                for i, text in zip(order[pos : pos + sizes[g]], texts):
                    out[i] = text
            if total > text_budget:
                raise CodecError("columnar payload renders more text than the window holds")
            pos += sizes[g]
        raw_positions = order[pos:]
        lengths, blob = read_blob(reader, len(raw_positions), "raw texts")
        for i, data in zip(raw_positions, split(blob, lengths, "raw text")):
            out[i] = str(data, "utf-8", UTF8_ERRORS)
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
