"""The columnar codec's encoder: groups of one shape become a template plus typed columns.

Apart from the codec (columnar.py) because it needs numpy, which readers do not import
(issue 14). The payload layout is specified in docs/CODEC_COLUMNAR.md.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np
import xxhash
import zstandard

from ..errors import CodecError
from .base import encode_texts, utf8_size
from .columnar_format import BODY_FACTOR, BODY_SLACK, GROUP_HEADER, HEADER, MAX_GROUPS, RAW_GROUP, U32, ColumnKind
from .columns import (
    _shuffle,
    _write_blob,
    _zigzag_delta,
    classify_columns,
    float_deltas,
    quaternion_prediction,
    slot_floats,
    write_column,
    write_packed,
)
from .shapes import ShapeMatcher, column_tokens


# A float slot after three float slots is coded as a quaternion's w when at least this
# share of its rows has x^2 + y^2 + z^2 + w^2 within 1e-6 of 1.
_QUATERNION_SHARE = 0.9
# A string slot with at most this many distinct values splits its group (see _split_by_label).
_MAX_LABELS = 8


def _split_by_label(
    literals: tuple[str, ...], indices: list[int], columns: list[Sequence[str] | str]
) -> list[tuple[tuple[str, ...], list[int], list[Sequence[str] | str]]]:
    """Split a group by its first string slot with a few values (a frame id, say).

    /tf interleaves transforms of different frames; apart, each frame's values form a
    smooth series that delta coding shrinks, together they alternate and do not.
    (A column is a sequence of tokens, or a number slot's str: `classify_joined`.)
    """
    if len(indices) < 2 * _MAX_LABELS:
        return [(literals, indices, columns)]
    for column in columns:
        if isinstance(column, str) or column[0][:1] != '"':
            continue
        labels = dict.fromkeys(column)  # in order of first appearance: the parts' order
        if 1 < len(labels) <= _MAX_LABELS:
            tokens = [column_tokens(c, len(indices)) for c in columns]
            parts = []
            for label in labels:
                rows = [r for r, token in enumerate(column) if token == label]
                parts.append((literals, [indices[r] for r in rows], [[c[r] for r in rows] for c in tokens]))
            return parts
    return [(literals, indices, columns)]


def _probe(kind: ColumnKind, vals: object, n: int) -> tuple[float, float] | None:
    """A slot's values at the rows `_maybe_unit` tests (the first and the middle): a
    FLOAT column's, a CONST token's float (both rows), else None. Taken once per slot,
    not once per test of each of the four quaternion slots it belongs to (issue 14)."""
    if kind is ColumnKind.FLOAT:
        return float(vals[0]), float(vals[n // 2])
    if kind is ColumnKind.CONST:
        try:
            value = float(vals)
        except ValueError:  # a string or true/false: not a quaternion's part
            return None
        return value, value
    return None


def _maybe_unit(probes: list[tuple[float, float] | None]) -> bool:
    """Whether the first or middle row of the probes of x, y, z, w is near unit: a cheap
    filter. A quaternion column has at least 90% unit rows, so it all but always passes;
    most float columns fail here without the numpy work of the full test.
    """
    if None in probes:
        return False
    for row in (0, 1):
        # c * c overflows to inf, not an error
        if abs(sum(probe[row] * probe[row] for probe in probes) - 1.0) < 1e-6:
            return True
    return False


def _encode_group(literals: tuple[str, ...], columns: list[Sequence[str] | str], n: int, version: int) -> bytes:
    """One group of n texts: header, literals, kinds, then each column's data."""
    kinds, values = [], []
    floats: list[np.ndarray | str | None] = []  # what slot_floats takes, per slot
    probes: list[tuple[float, float] | None] = []  # what _maybe_unit takes, per slot
    for kind, vals in classify_columns(columns, n, decimal=version >= 4):
        fl = vals if kind in (ColumnKind.FLOAT, ColumnKind.CONST) else None
        probe = _probe(kind, vals, n)
        if kind is ColumnKind.FLOAT and len(floats) >= 3 and _maybe_unit([*probes[-3:], probe]):
            xyz = [slot_floats(f, n) for f in floats[-3:]]
            if all(f is not None for f in xyz):
                x, y, z = xyz
                with np.errstate(all="ignore"):
                    near_unit = np.abs(x * x + y * y + z * z + vals * vals - 1.0) < 1e-6
                # the share as near_unit.mean() computes it (an exact count over n), in a cheaper call
                if np.count_nonzero(near_unit) / n >= _QUATERNION_SHARE:
                    kind = ColumnKind.QUAT_W
                    vals = vals.view("<u8") ^ quaternion_prediction(x, y, z).view("<u8")
        if kind is ColumnKind.FLOAT and version >= 3:
            kind = ColumnKind.FLOAT_DELTA
        elif kind is ColumnKind.INT and version >= 2:
            kind = ColumnKind.INT_OFFSET if version >= 3 else ColumnKind.INT_PACKED
        kinds.append(kind)
        values.append(vals)
        floats.append(fl)
        probes.append(probe)
    deltas = [j for j, kind in enumerate(kinds) if kind is ColumnKind.FLOAT_DELTA]
    if deltas:
        orders, planes = float_deltas(np.array([values[j] for j in deltas]).view("<i8"))
        for j, order, data in zip(deltas, orders, planes):
            values[j] = (order, data)
    out = bytearray(GROUP_HEADER.pack(n, len(kinds)))
    _write_blob([lit.encode() for lit in literals], [len(lit) for lit in literals], out)
    out += bytes(kinds)
    for kind, vals in zip(kinds, values):
        write_column(kind, vals, out)
    return bytes(out)


# A surrogate code point: an escaped byte that is not UTF-8 (see base), or a stray one.
_SURROGATE = re.compile("[\ud800-\udfff]")


def _shapeable(texts: Sequence[str]) -> list[str | None]:
    """The texts the shape matcher may see: those with a surrogate are stored verbatim."""
    if all(map(str.isascii, texts)):
        return list(texts)
    return [None if _SURROGATE.search(t) else t for t in texts]


def encode_window(compressor: zstandard.ZstdCompressor, matcher: ShapeMatcher, version: int,
                  stamps: Sequence[int], texts: Sequence[str]) -> bytes:  # fmt: skip
    """The payload of one window (`ColumnarCodec.encode`)."""
    count = len(stamps)
    if len(texts) != count:
        raise CodecError(f"a window needs one stamp per text, got {count} and {len(texts)}")
    try:
        stamp_words = np.array(stamps, dtype="<i8")
    except OverflowError as err:
        raise CodecError("a window stamp does not fit in a signed 64-bit integer") from err
    groups, _ = matcher.group_window(_shapeable(texts))
    ids = np.full(count, RAW_GROUP, dtype="<u2")
    bodies = []
    parts = [part for group in groups for part in _split_by_label(*group)]
    # No trial decode: a match rebuilds its text from the literals by construction,
    # and classify() keeps a column kind only if rendering it gives every token back.
    for literals, indices, columns in parts[:MAX_GROUPS]:
        if len(indices) == count:  # the usual window: one group holds every message
            ids.fill(len(bodies))
        else:
            ids[indices] = len(bodies)
        bodies.append(_encode_group(literals, columns, len(indices), version))
    raw_indices = np.flatnonzero(ids == RAW_GROUP).tolist()
    body = bytearray(U32.pack(len(bodies)))
    body += ids.tobytes()
    if version == 1:
        body += _shuffle(_zigzag_delta(stamp_words, 1))
    else:
        write_packed(stamp_words, body, offset=version >= 3)
    for data in bodies:
        body += data
    raw_texts = encode_texts([texts[i] for i in raw_indices])
    _write_blob(raw_texts, [len(t) for t in raw_texts], body)
    raw_len = 4 + 12 * count + utf8_size(texts)
    if len(body) > BODY_FACTOR * raw_len + BODY_SLACK:  # pragma: no cover - cannot happen
        raise CodecError("columnar body would exceed its decoding bound")
    frame = compressor.compress(bytes(body))
    return HEADER.pack(version, len(body), xxhash.xxh32_intdigest(frame)) + frame

