"""Typed value columns of the columnar codec: classify tokens, write them, read them back.

Every kind is chosen only when re-rendering its values gives each token back exactly
(`str(int)`, `repr(float)`, ...); anything else stays TEXT, which stores tokens verbatim.
"""

from __future__ import annotations

import base64
import functools
import math
import re
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

try:
    import simdjson
except ImportError:  # the fast float parser is optional: float() gives the same values
    simdjson = None

# The compiled byte planes (cclogfs/codecs/_planes.c, where setup.py could build it):
# write_packed and float_deltas in one call each, the same bytes as the numpy paths
# below, which took a dozen calls each (issue 14). Without it, those paths.
try:
    from ._planes import float_planes as _float_planes_c, pack_ints as _pack_ints_c
except ImportError:  # no C compiler at install
    _float_planes_c = _pack_ints_c = None

from ..errors import CodecError
from .columns_read import Reader, b64_token as _b64_token, read_blob as _read_blob, read_column, read_decimal, read_packed  # noqa: F401 (tests reach _read_blob here)
from .columns_read import float_text, orjson_rows, orjson_text, render_decimals as _render_decimals, render_floats
from .columnar_format import (
    DECIMAL_DIGITS,
    DECIMAL_ORDERS,
    FLOAT_ORDERS,
    MIN_BASE64_CHARS,
    OFFSET_HEADER,
    PACKED_HEADER,
    U32,
    ColumnKind,
)

__all__ = [
    "Reader",
    "read_packed",
    "write_packed",
    "classify",
    "classify_columns",
    "classify_joined",
    "float_deltas",
    "quaternion_prediction",
    "read_column",
    "read_decimal",
    "slot_floats",
    "write_column",
    "write_decimal",
]

_I64_MIN, _I64_MAX = -(1 << 63), (1 << 63) - 1
_BASE64 = re.compile(r'"(?:[A-Za-z0-9+/]{4})*(?:[A-Za-z0-9+/]{2}==|[A-Za-z0-9+/]{3}=)?"')
# Leading tokens of a column that decide whether its distinct tokens are checked apart.
_DEDUP_SAMPLE = 16
# Deltas per column that float_deltas ranks the orders on.
_ORDER_SAMPLES = 64
_local = threading.local()  # a simdjson parser is not thread-safe
# Columns shorter than this are parsed by float() or int() (see _parse_joined).
_SIMDJSON_MIN = 16
_NONFINITE = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}
# The encoder writes DECIMAL only for values m of at most 15 digits (the format allows
# any i64). A double holds every 15-digit decimal, so rounded values fit; the repr of an
# unrounded measurement needs 16 or 17, and a column of such reprs that merely share
# their length (a transform repeated with rare jumps) packs worse as integers than as
# float bits and loses the quaternion prediction: without this limit version 4 wrote
# /tf of nav2_turtlebot.mcap 1.1% larger than version 3 (137,554 against 136,020 bytes).
_DECIMAL_LIMIT = 10**15


def _render_floats(values: np.ndarray) -> list[str]:
    """Each value as json.dumps writes it: the text the decoder will render (columns_read)."""
    return render_floats(np.ascontiguousarray(values, dtype=np.float64))


def _render_joined(values: np.ndarray) -> str:
    """`render_floats(values)` joined by ",": the encoder compares it with a column's
    tokens joined, one string compare per column (orjson's text as it is, in the usual
    column)."""
    return _respelled(orjson_text(values), values)


# Below this magnitude json.dumps spells a float otherwise than orjson: repr's "1e-05" and
# "1e-07" are orjson's "0.00001" and "1e-7". So are NaN and the infinities (orjson: null).
# At 1e-4 and above the two agree (8.6M random doubles compared, issue 14; and
# tests/codecs/test_float_text.py). The bound is a little above 1e-4: respelling an item
# both spell alike gives the same text, so the boundary needs no exact argument. (The
# decoder, which imports no numpy, finds the same items by their text: columns_read.respell.)
_RESPELL_BELOW = 1.0001e-4


def _respell_mask(values: np.ndarray) -> np.ndarray:
    """Where `_respelled` must respell orjson's text of the values: any shape of array."""
    magnitude = np.abs(values)
    return ((magnitude < _RESPELL_BELOW) & (magnitude != 0)) | ~np.isfinite(magnitude)


def _respelled(text: str, values: np.ndarray, mask: np.ndarray | None = None) -> str:
    """orjson's text of the values with the items json.dumps spells otherwise respelled
    (float_text). The items are found on the values, `mask` (`_respell_mask(values)`,
    given by a caller that has it for many columns at once): looking for an exponent,
    null or "0.0000" in the text took three scans of every column (issue 14)."""
    where = np.flatnonzero(_respell_mask(values) if mask is None else mask)
    if not len(where):
        return text
    items = text.split(",")  # no item holds a comma: the i-th is values[i]'s
    for i, value in zip(where.tolist(), values[where].tolist()):
        # repr for a finite value (float_text's answer) without a call per item: robots
        # standing still write long runs of tiny velocities
        items[i] = repr(value) if value - value == 0 else float_text(value)
    return ",".join(items)


def _simdjson_parser():
    parser = getattr(_local, "parser", None)
    if parser is None:
        parser = _local.parser = simdjson.Parser()
    return parser


def _parse_joined(joined: str, n: int, of_type: str = "d") -> np.ndarray | None:
    """n tokens joined by "," parsed by simdjson in one call, as float64 (of_type "d") or
    int64 ("i"), or None if it refuses them or finds another count.

    Four times faster than float() per token, but a call costs a few microseconds:
    short columns (a constant's one token) go to float(). Nothing rests on simdjson
    parsing right: the caller keeps a value only if its rendering is the token.
    """
    if simdjson is None or n < _SIMDJSON_MIN:
        return None
    try:
        doc = _simdjson_parser().parse(("[" + joined + "]").encode())
        values = np.frombuffer(doc.as_buffer(of_type=of_type), dtype=np.float64 if of_type == "d" else np.int64)
        values = values.copy()
    except Exception:  # noqa: BLE001 - NaN, huge exponents, non-numbers: float() or int() decides
        return None
    return values if len(values) == n else None


def _as_floats(tokens: Sequence[str]) -> np.ndarray | None:
    """The tokens as float64, or None unless rendering them gives every token back."""
    joined = ",".join(tokens)
    parsed = _parse_joined(joined, len(tokens))
    if parsed is None:
        try:
            # float() also reads "NaN", "nan", "inf", "1_0", ...: the rendering check
            # below rejects every spelling the decoder would not write back.
            parsed = np.array(list(map(float, tokens)), dtype=np.float64)
        except ValueError:
            return None
    # Render exactly as the decoder will (json.dumps' text: so "nan" and "inf", which
    # repr writes, are refused), and compare all the tokens at once: parsed tokens hold
    # no comma (float() and simdjson refuse one, or the count differs), so equal joined
    # texts are equal tokens.
    return parsed if _render_joined(parsed) == joined else None


def classify(tokens: Sequence[str], decimal: bool = False) -> tuple[ColumnKind, Any]:
    """The most compact kind that reproduces every token, and the values to store.

    `decimal` allows DECIMAL (format version 4), whose values are (digits, i64 array).
    A number slot's tokens joined by "," go to `classify_joined`.
    """
    first = tokens[0]
    if tokens[-1] == first and tokens.count(first) == len(tokens):  # most columns vary: one compare
        return ColumnKind.CONST, first
    if first[:1] == '"':
        if len(first) >= MIN_BASE64_CHARS + 2 and all(map(_BASE64.fullmatch, tokens)):
            blobs = [base64.b64decode(t[1:-1]) for t in tokens]
            # Padding bits that are not zero ("QR==") decode but do not encode back.
            if all(_b64_token(b) == t for b, t in zip(blobs, tokens)):
                return ColumnKind.BASE64, blobs
        return ColumnKind.TEXT, tokens
    if first in ("true", "false") and all(t in ("true", "false") for t in tokens):
        return ColumnKind.BOOL, np.array([t == "true" for t in tokens], dtype=np.uint8)
    sample = tokens[:_DEDUP_SAMPLE]
    if len(set(sample)) == len(sample):
        return _numbers(tokens, decimal)
    # Seconds of a stamp, a velocity at rest: checking each distinct token once saves
    # most of the parsing and rendering. (A column whose first tokens are all distinct
    # skips this: collecting and mapping back would only add cost.)
    keys = tuple(dict.fromkeys(tokens))
    kind, values = _numbers(keys, decimal)
    if kind is ColumnKind.TEXT:
        return kind, tokens
    index = dict(zip(keys, range(len(keys))))
    rows = np.array(list(map(index.__getitem__, tokens)), dtype=np.intp)
    if kind is ColumnKind.DECIMAL:
        return kind, (values[0], values[1][rows])
    return kind, values[rows]


def classify_joined(joined: str, n: int, decimal: bool = False) -> tuple[ColumnKind, Any]:
    """`classify` of n number tokens joined by "," (as `shapes._columns` gives a number
    slot; a number token holds no comma, so `split(",")` gives them back), or of n copies
    of one token given once (a constant slot, as `shapes._columns` gives it).

    The usual columns are decided on the joined text, which is what simdjson parses and
    what orjson's rendering is compared with: a constant, and a column that is INT, or
    FLOAT and not DECIMAL, by the one-call checks of `_ints` and `_as_floats`. Each is the
    decision and the values the token path gives (its kinds are properties of each token,
    so whether it checks each distinct token once or all of them does not change them).
    Any other column (one the one-call checks refuse, a DECIMAL candidate, true/false)
    takes the token path. Issue 14, eighth pass: a token object per number cost more than
    checking it.
    """
    route = _route(joined, n, decimal)
    if isinstance(route, tuple):
        return route
    if route is not None:
        parsed = _parse_joined(joined, n, route)
        if parsed is not None and _rendered(parsed, route) == joined:
            return _ONE_CALL_KIND[route], parsed
    return classify(joined.split(","), decimal)


# The kind a one-call check of `_route` gives: simdjson's type letter to the column kind.
_ONE_CALL_KIND = {"i": ColumnKind.INT, "d": ColumnKind.FLOAT}


def _route(joined: str, n: int, decimal: bool) -> tuple[ColumnKind, str] | str | None:
    """How `classify_joined` decides a column: (CONST, its token); "i" or "d", the
    one-call check as INT or FLOAT; or None, the token path."""
    comma = joined.find(",")
    first = joined if comma < 0 else joined[:comma]
    if comma < 0 or (joined[joined.rfind(",") + 1 :] == first and ",".join([first] * n) == joined):
        return ColumnKind.CONST, first
    if first.isdigit() or (first[:1] == "-" and first[1:].isdigit()):
        return "i"
    if first not in ("true", "false") and not (decimal and _maybe_decimal(joined, first)):
        return "d"
    return None


def _rendered(values: np.ndarray, of_type: str) -> str:
    """The values joined as the decoder renders them: orjson's text for i64, which it
    writes as str(int) does; json.dumps' for floats (`_render_joined`)."""
    return orjson_text(values) if of_type == "i" else _render_joined(values)


def classify_columns(columns: Sequence[Sequence[str] | str], n: int, decimal: bool = False) -> list[tuple[ColumnKind, Any]]:
    """The kind and values of each column of a group of n texts: `classify_joined` of a
    number slot's joined tokens, `classify` of a list of tokens (`shapes._columns`).

    The same results, in fewer calls: the columns that take the one-call check of a type
    are parsed by one simdjson call and rendered by one orjson call together (values
    are read and written one by one, so each column's part is what it would be alone),
    then compared column by column. For a window of odometry (2 int and 7 float columns)
    that is 2 parses and 2 renderings where there were 9 of each, with the strings,
    buffers and arrays each call makes (issue 14). A group the joint parse refuses (one
    column of NaN, say) is decided column by column.
    """
    out: list[Any] = [None] * len(columns)
    checks: dict[str, list[int]] = {"i": [], "d": []}
    for j, column in enumerate(columns):
        if not isinstance(column, str):
            out[j] = classify(column, decimal)
            continue
        route = _route(column, n, decimal)
        if isinstance(route, tuple):
            out[j] = route
        elif route is None:
            out[j] = classify(column.split(","), decimal)
        else:
            checks[route].append(j)
    for of_type, members in checks.items():
        k = len(members)
        # Columns too short for simdjson take their path alone (see _parse_joined).
        parsed = _parse_joined(",".join([columns[j] for j in members]), k * n, of_type) if k > 1 and n >= _SIMDJSON_MIN else None
        if parsed is None:
            for j in members:
                out[j] = classify_joined(columns[j], n, decimal)
            continue
        rows = parsed.reshape(k, n)
        masks = _respell_mask(rows) if of_type == "d" else None  # one pass for every float column
        respell = masks.any(axis=1).tolist() if masks is not None else [False] * k
        for r, (j, row, text) in enumerate(zip(members, rows, orjson_rows(rows))):
            if respell[r]:
                text = _respelled(text, row, masks[r])
            out[j] = (_ONE_CALL_KIND[of_type], row) if text == columns[j] else classify(columns[j].split(","), decimal)
    return out


# A DECIMAL column's tokens joined, d digits after each point (render_decimals' text): a
# column the pattern misses is not DECIMAL, and is decided on its joined text (issue 14).
_FIXED_POINT = {d: re.compile(r"-?[0-9]+\.[0-9]{%d}(?:,-?[0-9]+\.[0-9]{%d})*" % (d, d)) for d in DECIMAL_DIGITS}


def _maybe_decimal(joined: str, first: str) -> bool:
    """Whether the joined tokens may be DECIMAL: every one fixed-point with the first's
    digits after the point. Float columns fail within a few tokens (repr's digit count
    varies); a column that passes takes the token path, which decides."""
    point = first.find(".")
    d = len(first) - point - 1
    return point >= 1 and d in _FIXED_POINT and _FIXED_POINT[d].fullmatch(joined) is not None


def _numbers(tokens: Sequence[str], decimal: bool = False) -> tuple[ColumnKind, Any]:
    """INT, DECIMAL or FLOAT with the values, if rendering gives every token back; else TEXT."""
    # Only a column of canonical ints is INT, so one whose first token is not digits
    # (a float) skips int(), which would raise on it: the outcome is the same.
    first = tokens[0]
    if first.isdigit() or (first[:1] == "-" and first[1:].isdigit()):
        found = _ints(tokens)
        if found is not None:
            return found
    # Before FLOAT: "0.125" is both, and an integer of 3 digits packs far tighter than
    # its float64 bits. A column of repr floats fails at its first token of other length.
    decimals = _as_decimals(tokens) if decimal else None
    if decimals is not None:
        return ColumnKind.DECIMAL, decimals
    floats = _as_floats(tokens)
    if floats is not None:
        return ColumnKind.FLOAT, floats
    return ColumnKind.TEXT, tokens


def _ints(tokens: Sequence[str]) -> tuple[ColumnKind, Any] | None:
    """INT with the values if every token is an i64 as str(int) writes it; TEXT if every
    token reads as an int but one is written otherwise ("+1", "007") or does not fit;
    None if one does not read as an int (then it may be a float)."""
    joined = ",".join(tokens)
    # The usual column, in two calls: simdjson reads it, and orjson writes an i64 as
    # str(int) does; a column they refuse is decided by int() below, as before.
    parsed = _parse_joined(joined, len(tokens), "i")
    if parsed is not None and orjson_text(parsed) == joined:
        return ColumnKind.INT, parsed
    try:
        ints = list(map(int, tokens))
    except ValueError:
        return None
    # As for floats: an int's repr has no comma, so one list repr compares all.
    exact = repr(ints) == "[" + ", ".join(tokens) + "]"
    if exact and _I64_MIN <= min(ints) and max(ints) <= _I64_MAX:
        return ColumnKind.INT, np.array(ints, dtype=np.int64)
    return ColumnKind.TEXT, tokens


def _as_decimals(tokens: Sequence[str]) -> tuple[int, np.ndarray] | None:
    """(d, the values m) if every token is fixed-point with d digits that renders back.

    m is the token without its point, |m| < 10^15 (see _DECIMAL_LIMIT). The rendering
    check refuses "-0.000", "+1.5", "01.5", "1_0.5" and ".5", which int() or the point's
    position alone would let pass.
    """
    first = tokens[0]
    point = first.find(".")
    d = len(first) - point - 1
    if point < 1 or d not in DECIMAL_DIGITS:
        return None
    for t in tokens:  # cheap: most float columns fail at their second token
        if t[-d - 1 : -d] != ".":
            return None
    try:
        values = [int(t[: -d - 1] + t[-d:]) for t in tokens]
    except ValueError:
        return None
    if not (-_DECIMAL_LIMIT < min(values) and max(values) < _DECIMAL_LIMIT):
        return None
    if _render_decimals(values, d) != list(tokens):
        return None
    return d, np.array(values, dtype=np.int64)


def _decimal_words(values: np.ndarray, order: int) -> np.ndarray:
    """The values with order - 1 repeated differences taken (first value kept; wraps)."""
    words = values.astype("<i8", copy=True)
    for _ in range(order - 1):
        words[1:] = np.diff(words)
    return words


def write_decimal(d: int, values: np.ndarray, out: bytearray) -> None:
    """Append a DECIMAL column: u8 d, u8 order, offset(n) of the (order-1)-th differences.

    Offset packing takes one more difference, so order r stores r-th differences minus
    their smallest. The order is the one whose stored values have the fewest significant
    bits in sum (ties: the lowest): noisy velocities take 1, smooth series often 2.
    The packed width alone ranks them worse (it picked 1 for every column of rounded
    /odom): one outlier sets it for the whole column, and zstd packs the bits below it.
    """
    best_cost, best = math.inf, values
    order = DECIMAL_ORDERS[0]
    for r in DECIMAL_ORDERS:
        words = _decimal_words(values, r)
        deltas = np.diff(words).astype(np.float64)  # wrapped, as the packing sees them
        cost = float(np.log2(deltas - deltas.min() + 1.0).sum()) if len(deltas) else 0.0
        if cost < best_cost:
            best_cost, best, order = cost, words, r
    out += bytes((d, order))
    write_packed(best, out, offset=True)


def slot_floats(entry: np.ndarray | str | None, n: int) -> np.ndarray | None:
    """Float values of a slot: its column, or a CONST token repeated, or None.

    Constants are converted only here, when a quaternion needs them: most slots of a
    message are constants, and converting each would cost more than the whole group.
    """
    if entry is None or isinstance(entry, np.ndarray):
        return entry
    value = _const_float(entry)
    return None if value is None else np.full(n, value)


@functools.lru_cache(maxsize=256)
def _const_float(token: str) -> float | None:
    """A CONST token's float, if rendering it gives the token back. Cached: the same few
    constants (a quaternion's x and y of 0.0) are asked for in window after window."""
    arr = _as_floats((token,))
    return None if arr is None else float(arr[0])


def quaternion_prediction(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """sqrt(1 - x^2 - y^2 - z^2), with 0.0 wherever that is not a finite number.

    Every step is a correctly rounded IEEE operation, so encoder and decoder compute the
    same bits on any platform; non-finite results (whose NaN bits differ by CPU) become 0.
    """
    with np.errstate(all="ignore"):
        pred = np.sqrt(1.0 - x * x - y * y - z * z)
    pred[~np.isfinite(pred)] = 0.0
    return pred


def _shuffle(words: np.ndarray) -> bytes:
    """Byte planes of 8-byte words: byte 0 of every value, then byte 1, ..."""
    return words.view(np.uint8).reshape(len(words), 8).T.tobytes()


def _zigzag_delta(words: np.ndarray, order: int) -> np.ndarray:
    d = words.astype("<i8", copy=True)
    for _ in range(order):
        d[1:] = np.diff(d)  # wraps modulo 2**64, which undo_delta reverses exactly
    return ((d << 1) ^ (d >> 63)).view("<u8")


def write_packed(words: np.ndarray, out: bytearray, offset: bool = False) -> None:
    """Append i64 values as: first, step (gcd of the deltas), [base,] width, width byte planes.

    Stamps in microseconds or a 36 ms period leave the low bits of every delta zero and
    its high bytes empty; dividing by the step and dropping empty planes saves both.
    With `offset` (version 3) the smallest quotient is subtracted instead of zigzag
    coding: deltas of a steady rate (36 ms +- jitter) then need 2 planes, not 3.
    Nothing is written for no values.
    """
    n = len(words)
    if n == 0:
        return
    words = words.astype("<i8", copy=False)
    if _pack_ints_c is not None:
        out += _pack_ints_c(np.ascontiguousarray(words), offset)
        return
    deltas = words[1:] - words[:-1]  # wraps modulo 2**64, as the cumsum that undoes it
    smallest = int(deltas.min()) if n > 1 else 0
    if smallest > _I64_MIN:  # numpy's gcd takes abs(), which -2**63 overflows
        step = int(np.gcd.reduce(deltas)) if n > 1 else 0
    else:
        step = math.gcd(*deltas.tolist())
    if step > _I64_MAX:  # every delta is 0 or -2**63: keep them whole
        step = 1
    # A step of 1 (nanosecond stamps) leaves the deltas as they are: no division, and
    # their smallest is already known (issue 14: numpy's calls cost more than its work).
    q = deltas if step == 1 else deltas // step if step else np.zeros(n - 1, dtype="<i8")
    if offset:
        base = smallest if step == 1 else int(q.min()) if n > 1 else 0
        z = (q - np.int64(base)).view("<u8")  # wraps: max - min < 2**64 always fits in u64
    else:
        z = ((q << 1) ^ (q >> 63)).view("<u8")
    width = (int(z.max()).bit_length() + 7) // 8 if n > 1 else 0
    if offset:
        out += OFFSET_HEADER.pack(int(words[0]), step, base, width)
    else:
        out += PACKED_HEADER.pack(int(words[0]), step, width)
    out += z.view(np.uint8).reshape(n - 1, 8)[:, :width].T.tobytes()


def float_deltas(bits: np.ndarray) -> tuple[list[int], list[memoryview]]:
    """For rows of f64 bits (k x n): each row's delta order and its FLOAT_DELTA planes.

    The order is the one in FLOAT_ORDERS leaving the fewest significant bits (the sum,
    over a sample of deltas, of frexp's exponent of each as a double, an exact integer;
    ties: the lowest order): positions are smooth (second or third order wins),
    velocities are noisy steps (first order wins). All float columns of a group go
    through numpy at once: per column, the calls would cost more than the arithmetic.
    The levels live in one array, so the sample and the chosen rows are views and one
    gather, not stacks; each difference is taken over a level's rows end to end, one
    contiguous subtraction, and the first column, which that gets wrong, is then set
    (per row, numpy's calls took more time than its arithmetic; issue 14).
    """
    if bits.dtype.kind not in "iu" or bits.dtype.itemsize != 8:  # the bits, not the floats
        raise TypeError(f"float_deltas takes 64-bit words (a float64 array's .view('<i8')), not {bits.dtype}")
    bits = bits.astype("<i8", copy=False)  # u8 words as i8: the same bits, signed shifts
    k, n = bits.shape
    if _float_planes_c is not None:
        orders, data = _float_planes_c(np.ascontiguousarray(bits), k, n)
        planes = memoryview(data)
        return orders, [planes[8 * n * j : 8 * n * (j + 1)] for j in range(k)]
    top = FLOAT_ORDERS[-1]  # the orders are 1..top (columnar_format)
    flat = np.empty((top + 1, k * n), dtype=bits.dtype)
    flat[0] = bits.ravel()
    for r in FLOAT_ORDERS:  # level r: the r-th repeated difference, first value kept
        np.subtract(flat[r - 1, 1:], flat[r - 1, :-1], out=flat[r, 1:])  # wraps modulo 2**64
        flat[r, ::n] = flat[0, ::n]
    levels = flat.reshape(top + 1, k, n)
    if n > top:
        stride = max(1, n // _ORDER_SAMPLES)  # a sample ranks the orders as well as all rows
        sample = levels[1:, :, top::stride]
        cost = np.frexp(np.abs(sample.astype(np.float64)))[1].sum(axis=2)  # orders x k
        chosen_levels = cost.argmin(axis=0) + 1
        orders = chosen_levels.tolist()
    else:
        orders = [2] * k
        chosen_levels = np.full(k, 2)
    chosen = levels[chosen_levels, np.arange(k)]
    z = ((chosen << 1) ^ (chosen >> 63)).view("<u8")
    planes = memoryview(z.view(np.uint8).reshape(k, n, 8).transpose(0, 2, 1).tobytes())
    return orders, [planes[8 * n * j : 8 * n * (j + 1)] for j in range(k)]


def _write_blob(parts: list[bytes], counts: list[int], out: bytearray) -> None:
    blob = b"".join(parts)
    out += np.array(counts, dtype="<u4").tobytes()
    out += U32.pack(len(blob))
    out += blob


def write_column(kind: ColumnKind, values: Any, out: bytearray) -> None:
    """Append one column's data (not its kind byte) to out."""
    if kind is ColumnKind.CONST:
        data = values.encode()
        out += U32.pack(len(data)) + data
    elif kind is ColumnKind.TEXT:
        _write_blob([t.encode() for t in values], [len(t) for t in values], out)
    elif kind is ColumnKind.INT:
        out += _shuffle(_zigzag_delta(values, 1))
    elif kind is ColumnKind.INT_PACKED:
        write_packed(values, out)
    elif kind is ColumnKind.INT_OFFSET:
        write_packed(values, out, offset=True)
    elif kind is ColumnKind.FLOAT:
        out += _shuffle(_zigzag_delta(values.view("<i8"), 2))
    elif kind is ColumnKind.FLOAT_DELTA:
        order, planes = values  # from float_deltas
        out.append(order)
        out += planes
    elif kind is ColumnKind.DECIMAL:
        write_decimal(*values, out)
    elif kind is ColumnKind.QUAT_W:
        out += _shuffle(values)  # the residual bits, computed by the caller
    elif kind is ColumnKind.BOOL:
        out += values.tobytes()
    elif kind is ColumnKind.BASE64:
        _write_blob(values, [len(v) for v in values], out)
    else:  # pragma: no cover - classify only returns the kinds above
        raise CodecError(f"columnar codec cannot write column kind {kind!r}")
