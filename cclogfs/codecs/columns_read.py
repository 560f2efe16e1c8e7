"""Reading the columns of the columnar codec back, in plain Python (no numpy).

Decoding is what `cclog cat` of one second does, and importing numpy cost that command
more than everything else (issue 14). A window's columns hold a few hundred values each,
where the standard library keeps up with numpy: byte planes are put back together by
slice assignment, words unpacked by struct, and differences undone by accumulate on
Python integers, wrapped to 64 bits once at the end (wrapping is arithmetic modulo 2**64,
so once at the end gives the bits numpy's wrapping int64 gives at every step).
The layout is specified in docs/CODEC_COLUMNAR.md; `columns` writes it.
"""

from __future__ import annotations

import binascii
import functools
import math
import struct
from itertools import accumulate

import orjson

from ..errors import CodecError
from .columnar_format import DECIMAL_DIGITS, DECIMAL_ORDERS, FLOAT_ORDERS, OFFSET_HEADER, PACKED_HEADER, U32, ColumnKind

_I64_MAX = (1 << 63) - 1
_SIGN, _MASK = 1 << 63, (1 << 64) - 1


class Reader:
    """Reads a body front to back; every length is checked before anything is allocated."""

    def __init__(self, data: bytes):
        self.view = memoryview(data)
        self.pos = 0

    def take(self, n: int, what: str) -> memoryview:
        if n < 0 or n > len(self.view) - self.pos:
            raise CodecError(
                f"columnar payload is corrupt: {what} at body offset {self.pos} needs {n} "
                f"bytes, {len(self.view) - self.pos} are left"
            )
        self.pos += n
        return self.view[self.pos - n : self.pos]

    def u32(self, what: str) -> int:
        return U32.unpack(self.take(4, what))[0]

    def ints(self, code: str, n: int, what: str) -> tuple[int, ...]:
        """n little-endian integers of struct type `code` ("H", "I")."""
        fmt = struct.Struct(f"<{n}{code}")
        return fmt.unpack(self.take(fmt.size, what))

    def planes(self, n: int, width: int, what: str) -> bytearray:
        """n u64 stored as `width` byte planes (byte 0 of every word, then byte 1, ...),
        as 8n little-endian bytes; the planes not stored are zero."""
        planes = self.take(width * n, what)
        buf = bytearray(8 * n)
        for j in range(width):
            buf[j::8] = planes[j * n : (j + 1) * n]
        return buf

    def words(self, n: int, width: int, what: str) -> list[int]:
        """The n u64 of `planes`."""
        return list(struct.unpack(f"<{n}Q", self.planes(n, width, what)))

    def zigzag(self, n: int, width: int, what: str) -> tuple[int, ...]:
        """The n i64 whose zigzag codes are the u64 of `planes`."""
        return unzigzag(self.planes(n, width, what), n)


@functools.lru_cache(maxsize=64)
def _lane_masks(n: int) -> tuple[int, int]:
    """For n 64-bit words in one integer: the lowest bit of each, and all bits but the highest."""
    every = int.from_bytes((b"\1" + bytes(7)) * n, "little")  # 1 in each word
    return every, every * (_MASK >> 1)


def unzigzag(buf: bytes | bytearray, n: int) -> tuple[int, ...]:
    """The i64 values of the n zigzag codes v (little-endian u64) in `buf`: each is
    (v >> 1) ^ -(v & 1), computed for every word at once on the one integer the bytes
    make (a column is a few hundred words; a loop per word was the decoder's costliest
    line): shifting it right moves each word's lowest bit into the word below, which
    the mask clears; the words whose code was odd are then inverted (XOR with 2**64 - 1,
    which the lowest bit times 2**64 - 1 is); the words read back as signed."""
    low, keep = _lane_masks(n)
    x = int.from_bytes(buf, "little")
    y = ((x >> 1) & keep) ^ ((x & low) * _MASK)
    return struct.unpack(f"<{n}q", y.to_bytes(8 * n, "little"))


def _signed(values) -> list[int]:
    """Integers wrapped to signed 64 bits (most columns never wrap: min and max say so at
    C speed, and the list is returned as it is)."""
    values = list(values)
    if values and (min(values) < -_SIGN or max(values) >= _SIGN):
        return [((v + _SIGN) & _MASK) - _SIGN for v in values]
    return values


def undo_zigzag_delta(z: list[int], order: int) -> list[int]:
    """The i64 values whose `order`-th differences were zigzag coded as `z`."""
    return _signed(_sums(unzigzag(struct.pack(f"<{len(z)}Q", *z), len(z)), order))


def _sums(d, order: int):
    """The values whose `order`-th differences are `d` (not yet wrapped to 64 bits)."""
    for _ in range(order):
        d = accumulate(d)
    return d


def _doubles(words) -> list[float]:
    """The floats whose 64 bits the words are, modulo 2**64 (sums of differences taken in
    wrapping i64 arithmetic may lie outside: masked then, a cheaper wrap than _signed's)."""
    words = list(words)
    n = len(words)
    code = "q"
    if words and (min(words) < -_SIGN or max(words) >= _SIGN):
        words, code = [v & _MASK for v in words], "Q"
    return list(struct.unpack(f"<{n}d", struct.pack(f"<{n}{code}", *words)))


def float_text(value: float) -> str:
    """A float the way json.dumps writes it."""
    if value != value:
        return "NaN"
    if value in (math.inf, -math.inf):
        return "Infinity" if value > 0 else "-Infinity"
    return repr(value)


def render_floats(values) -> list[str]:
    """Each value as json.dumps writes it (repr; NaN, Infinity): a list of floats, or a
    contiguous float64 numpy array (the encoder's check renders what the decoder will).

    orjson writes floats 6-10x faster than repr, in the same shortest round-trip digits,
    but spells two ranges differently: exponents ("1e-7" for repr's "1e-07") and the
    decade below 1e-4, which it writes in full ("0.00001" for "1e-05"); NaN and
    infinities it writes as null. Those items, rare in robot data, are rendered by
    float_text. tests/codecs/test_float_text.py holds this to json.dumps.
    """
    if len(values) == 0:
        return []
    return respell(orjson_text(values), values)


def respell(text: str, values) -> list[str]:
    """`orjson_text(values)` cut into items, each that orjson may spell otherwise than
    json.dumps spelled by float_text (see render_floats)."""
    texts = text.split(",")
    if orjson_differs(text):  # one scan of the whole column first
        # A few more items than needed (repr is right for all); the test of
        # orjson_differs written out, as a call per item took half the column's time.
        for i in [i for i, t in enumerate(texts) if "e" in t or "n" in t or "0.0000" in t]:
            texts[i] = float_text(float(values[i]))
    return texts


# What orjson_differs looks for: an exponent, null, the decade below 1e-4.
_MARKS = ("e", "n", "0.0000")


def orjson_text(values) -> str:
    """The values (floats, or numpy floats or ints) as orjson writes them, comma-separated,
    without the brackets."""
    return orjson.dumps(values, option=orjson.OPT_SERIALIZE_NUMPY)[1:-1].decode()


def orjson_rows(rows) -> list[str]:
    """`orjson_text` of each row of a 2-D numpy array, from one call: orjson writes the
    rows one after another as it writes each alone, and no item holds a bracket.

    Cut at each "]" found by str.find (memchr), not by split("],["): splitting on three
    characters took 26 us for 7 rows of 200 floats, the cuts take 6 (issue 14)."""
    text = orjson.dumps(rows, option=orjson.OPT_SERIALIZE_NUMPY)[2:-2].decode()
    out, at, find = [], 0, text.find
    while (end := find("]", at)) >= 0:  # "],[" between rows
        out.append(text[at:end])
        at = end + 3
    out.append(text[at:])
    return out


def orjson_differs(text: str) -> bool:
    """Whether orjson's text may not be json.dumps' (it holds one of _MARKS)."""
    return "e" in text or "n" in text or "0.0000" in text


def render_decimals(values: list[int], d: int) -> list[str]:
    """m with its point d digits from the right: -5, 3 -> "-0.005"; zero has no sign."""
    out = []
    for m in values:
        digits = str(-m if m < 0 else m).zfill(d + 1)
        out.append(("-" if m < 0 else "") + digits[:-d] + "." + digits[-d:])
    return out


def read_packed(reader: Reader, n: int, what: str, offset: bool = False) -> list[int]:
    """The n i64 values `columns.write_packed` wrote."""
    if n == 0:
        return []
    if offset:
        first, step, base, width = OFFSET_HEADER.unpack(reader.take(OFFSET_HEADER.size, f"{what} header"))
    else:
        first, step, width = PACKED_HEADER.unpack(reader.take(PACKED_HEADER.size, f"{what} header"))
        base = 0
    if width > 8 or step > _I64_MAX:
        raise CodecError(f"columnar payload is corrupt: {what} claims step {step} and {width}-byte deltas")
    if offset:
        words = reader.words(n - 1, width, what)
        deltas = list(map(base.__add__, words)) if step == 1 else [(v + base) * step for v in words]
    else:
        z = reader.zigzag(n - 1, width, what)
        deltas = [v * step for v in z] if step != 1 else list(z)
    deltas.insert(0, first)
    return _signed(accumulate(deltas))


def read_decimal(reader: Reader, n: int) -> list[str]:
    """The rendered tokens of a DECIMAL column."""
    d, order = reader.take(2, "decimal column header").tolist()
    if d not in DECIMAL_DIGITS or order not in DECIMAL_ORDERS:
        raise CodecError(
            f"columnar payload is corrupt: a decimal column names {d} digits "
            f"and delta order {order}"
        )
    words = read_packed(reader, n, "decimal column", offset=True)
    for _ in range(order - 1):
        words = accumulate(words)  # the encoder's differences, undone
    return render_decimals(_signed(words), d)


def const_float(token: str) -> float | None:
    """A CONST token's float, if rendering it gives the token back."""
    try:
        value = float(token)
    except ValueError:
        return None
    return value if render_floats([value]) == [token] else None


def slot_values(entry: list[float] | str | None, n: int) -> list[float] | None:
    """Float values of a slot read so far: its column, or a CONST token repeated, or None."""
    if entry is None or isinstance(entry, list):
        return entry
    value = const_float(entry)
    return None if value is None else [value] * n


def quaternion_w(x: list[float], y: list[float], z: list[float]) -> list[float]:
    """sqrt(1 - x^2 - y^2 - z^2), with 0.0 wherever that is not a finite number: the bits
    `columns.quaternion_prediction` computes (each step a correctly rounded IEEE operation,
    in the same order)."""
    sqrt = math.sqrt
    squares = [1.0 - a * a - b * b - c * c for a, b, c in zip(x, y, z)]
    return [sqrt(s) if s >= 0.0 else 0.0 for s in squares]  # NaN and -inf fail the test


def read_blob(reader: Reader, n: int, what: str) -> tuple[tuple[int, ...], memoryview]:
    counts = reader.ints("I", n, f"{what} lengths")
    blob = reader.take(reader.u32(f"{what} size"), what)
    return counts, blob


def split(text, counts: tuple[int, ...], what: str) -> list:
    """`text` (str or bytes) cut into pieces of the given lengths, which must add up to it."""
    if sum(counts) != len(text):
        raise CodecError(f"columnar payload is corrupt: {what} lengths do not add up")
    ends = list(accumulate(counts))
    return [text[a:b] for a, b in zip([0, *ends[:-1]], ends)]


def read_column(kind: int, reader: Reader, n: int, floats: list) -> tuple[list[str] | str, list[float] | None]:
    """(rendered tokens, or one token for CONST; float values or None) of one column.

    `floats` holds, for the slots read so far, what `slot_values` takes (QUAT_W needs three).
    """
    if kind == ColumnKind.CONST:
        data = reader.take(reader.u32("constant size"), "constant")
        return utf8(data, "constant"), None
    if kind == ColumnKind.TEXT:
        counts, blob = read_blob(reader, n, "text column")
        return split(utf8(blob, "text column"), counts, "text column"), None
    if kind == ColumnKind.INT:
        return list(map(str, _signed(_sums(reader.zigzag(n, 8, "int column"), 1)))), None
    if kind in (ColumnKind.INT_PACKED, ColumnKind.INT_OFFSET):
        return list(map(str, read_packed(reader, n, "int column", offset=kind == ColumnKind.INT_OFFSET))), None
    if kind in (ColumnKind.FLOAT, ColumnKind.FLOAT_DELTA):
        order = 2
        if kind == ColumnKind.FLOAT_DELTA:
            order = int(reader.take(1, "float delta order")[0])
            if order not in FLOAT_ORDERS:
                raise CodecError(f"columnar payload is corrupt: a float column names delta order {order}")
        values = _doubles(_sums(reader.zigzag(n, 8, "float column"), order))
        return render_floats(values), values
    if kind == ColumnKind.DECIMAL:
        return read_decimal(reader, n), None
    if kind == ColumnKind.QUAT_W:
        xyz = [slot_values(f, n) for f in floats[-3:]]
        if len(xyz) < 3 or any(f is None for f in xyz):
            raise CodecError("columnar payload is corrupt: a quaternion column lacks x, y, z")
        residual = int.from_bytes(reader.planes(n, 8, "quaternion column"), "little")
        predicted = int.from_bytes(struct.pack(f"<{n}d", *quaternion_w(*xyz)), "little")
        values = list(struct.unpack(f"<{n}d", (residual ^ predicted).to_bytes(8 * n, "little")))  # XOR of each word
        return render_floats(values), values
    if kind == ColumnKind.BOOL:
        flags = reader.take(n, "bool column").tolist()
        if any(f > 1 for f in flags):
            raise CodecError("columnar payload is corrupt: a bool column holds a value above 1")
        return [("false", "true")[f] for f in flags], None
    if kind == ColumnKind.BASE64:
        counts, blob = read_blob(reader, n, "base64 column")
        return [b64_token(b) for b in split(bytes(blob), counts, "base64 column")], None
    raise CodecError(f"columnar payload is corrupt: unknown column kind {kind}")


def b64_token(data: bytes) -> str:
    return '"' + binascii.b2a_base64(data, newline=False).decode("ascii") + '"'


def utf8(data: memoryview, what: str) -> str:
    try:
        return str(data, "utf-8")
    except UnicodeDecodeError as err:
        raise CodecError(f"columnar payload is corrupt: {what} is not UTF-8") from err
