"""Mirror of docs/CODEC_COLUMNAR.md: the numbers of the columnar codec's payload format."""

from __future__ import annotations

import struct
from enum import IntEnum

# Payload versions this code decodes; the encoder writes the one its config names.
FORMAT_VERSIONS = (1, 2, 3, 4)
LATEST_VERSION = 4

HEADER = struct.Struct("<BII")  # format version, body length (before zstd), xxh32 of the frame
GROUP_HEADER = struct.Struct("<II")  # messages in the group, value slots per message
U32 = struct.Struct("<I")
# Packed integers (version 2): first value, step dividing every delta, bytes per delta.
PACKED_HEADER = struct.Struct("<qQB")
# Offset-packed integers (version 3): first value, step, smallest quotient, bytes per delta.
OFFSET_HEADER = struct.Struct("<qQqB")
# Delta orders a FLOAT_DELTA column may name (version 3).
FLOAT_ORDERS = (1, 2, 3)
# Digits after the point a DECIMAL column may name (version 4): with 19, no i64 reaches 1.
DECIMAL_DIGITS = range(1, 19)
# Delta orders a DECIMAL column may name (version 4): offset(n) itself takes the first.
DECIMAL_ORDERS = (1, 2, 3)

# Group id of messages stored as plain text (no shape, or the shape did not reproduce them).
RAW_GROUP = 0xFFFF
MAX_GROUPS = 0xFFFE

# A body is at most this many times raw_len (plus BODY_SLACK): an int column spends 8
# bytes on a value the text wrote in 1 digit. The decoder refuses larger claims.
BODY_FACTOR = 9
BODY_SLACK = 1024

# Base64 strings shorter than this stay text: decoding them saves too little.
MIN_BASE64_CHARS = 64


class ColumnKind(IntEnum):
    """How one value slot of a shape is stored. Values never change; 0 is invalid."""

    CONST = 1  # one token for every message
    TEXT = 2  # tokens verbatim: u32 char count each, then u32 byte count + UTF-8 blob
    INT = 3  # i64, delta + zigzag, byte-shuffled
    FLOAT = 4  # f64 bits, second-order delta + zigzag, byte-shuffled; rendered as repr
    BOOL = 5  # u8 0/1: false/true
    BASE64 = 6  # decoded bytes: u32 length each, then the bytes; rendered as "base64"
    QUAT_W = 7  # f64 bits XOR sqrt(1 - x^2 - y^2 - z^2) of the three slots before
    INT_PACKED = 8  # version 2: i64 as packed integers (first, step, narrow zigzag deltas)
    FLOAT_DELTA = 9  # version 3: u8 delta order, then f64 bits as in FLOAT with that order
    INT_OFFSET = 10  # version 3: i64 as offset-packed integers (first, step, base, narrow deltas)
    DECIMAL = 11  # version 4: u8 digits, u8 delta order, offset-packed i64 (token without its point)


# The kinds each format version may hold; the decoder refuses any other.
VERSION_KINDS = {
    1: frozenset(range(1, 8)),
    2: frozenset(range(1, 9)),
    3: frozenset(range(1, 11)) - {ColumnKind.INT_PACKED, ColumnKind.FLOAT},
    4: frozenset(range(1, 12)) - {ColumnKind.INT_PACKED, ColumnKind.FLOAT},
}
