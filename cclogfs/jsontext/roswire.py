"""ROS messages from their serialized bytes (ROS 1 or CDR) straight to rosbridge JSON text.

`ros.py` converts rosbags' message objects: rosbags deserializes each message into
dataclasses and numpy arrays, `to_dict` turns them into dicts and lists, and `json.dumps`
walks those. Recording a bag spent most of its time there (issue 14). Here, once per
message type, `roswire_gen` writes the source of a function that reads the type's bytes
with `struct` and returns an f-string of its JSON text: `f'{{"header": {{"seq": {t0}, ...'`,
its numbers rendered by one orjson call (`number_texts`). A `nav_msgs/Odometry` is then
three struct reads, two strings, two memo look-ups, one orjson call and the f-string.

The text is byte for byte `MessageConverter().to_json(typestore.deserialize_*(raw))`
(tests/jsontext/test_roswire.py compares every message of the shared data and random
messages of every type rosbags ships), and a message is accepted exactly when rosbags
accepts it: the generated code repeats rosbags' reads, CDR alignment steps and length
checks (rosbags/serde/ros1.py, cdr.py) in the same order.

Print a type's generated source with `formatter_source` or
`python -m cclogfs.jsontext.roswire BAG TYPE`.

This module holds what the generated functions call (string, sequence and float
helpers) and `WireFormatter`, which generates, compiles and caches them.
"""

from __future__ import annotations

import base64
import struct
import sys
from collections.abc import Callable
from json.encoder import encode_basestring_ascii as json_string  # what json.dumps uses
from typing import Any

import orjson

from .roswire_gen import Unsupported, module_source

__all__ = ["WireError", "WireFormatter", "formatter_source"]

# A formatter: the message's serialized bytes -> (JSON text, header.stamp in ns or None).
Format = Callable[[bytes], tuple[str, "int | None"]]


class WireError(ValueError):
    """Bytes that are not a message of the type: `field` names where (`header.frame_id`,
    `transforms[3].header.stamp.sec`), `reason` says what was wrong."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"field {field or '(message)'}: {reason}")
        self.field = field
        self.reason = reason

    @classmethod
    def wrap(cls, field: str, err: Exception) -> WireError:
        """`err`, raised reading `field`: struct's and the helpers' messages say what was
        wrong (a buffer too short, a bad length, invalid UTF-8); others get their type named."""
        plain = isinstance(err, (ValueError, struct.error))
        return cls(field, str(err) if plain else f"{err.__class__.__name__}: {err}")

    def inside(self, outer: str) -> WireError:
        """The same error seen from the message holding this one as `outer`."""
        return WireError(f"{outer}.{self.field}" if self.field else outer, self.reason)


def json_number(value: int | float) -> str:
    """One number as json.dumps writes it: repr, except NaN and the infinities, which
    repr spells `nan` and `inf` and json.dumps `NaN`, `Infinity` and `-Infinity`."""
    if value - value == 0:  # ints, and finite floats
        return repr(value)
    return "NaN" if value != value else "Infinity" if value > 0 else "-Infinity"


def _orjson_may_differ(text: str) -> bool:
    """Whether orjson's text of numbers may not be json.dumps': an exponent, `null` (its
    NaN and infinities), or the decade below 1e-4, which orjson writes in full (`0.00001`,
    repr `1e-05`). The columnar codec's rule (codecs/columns_read.py); every other float,
    and every int, has the same text in both."""
    return "e" in text or "n" in text or "0.0000" in text


def number_texts(values: tuple) -> list[str]:
    """The JSON text of each number (ints or floats; at least one), as json.dumps writes it.

    orjson writes shortest round-trip floats as repr does, 3-4x faster than `%r` per
    float (issue 14: rendering floats was most of formatting a message); the few tokens
    it may write otherwise are rendered again with repr.
    """
    text = orjson.dumps(values)[1:-1].decode()
    tokens = text.split(",")
    if _orjson_may_differ(text):
        tokens = [json_number(v) if _orjson_may_differ(t) else t for v, t in zip(values, tokens)]
    return tokens


def numbers(values: tuple) -> str:
    """A JSON array of numbers as json.dumps writes it."""
    if not values:
        return "[]"
    text = orjson.dumps(values)[1:-1].decode()
    if _orjson_may_differ(text):
        return "[" + ", ".join(number_texts(values)) + "]"
    return "[" + text.replace(",", ", ") + "]"  # numbers hold no comma


class ArrayMemo:
    """The JSON text of one fixed-size numeric array field, remembered by its bytes.

    A covariance is often the same in every message (a placeholder, a fixed sensor model):
    in the shared data every one is. Rendering its 36 floats was half of formatting an
    Odometry; looking its 288 bytes up costs a tenth of that. Keyed by the bytes, not the
    values: -0.0 == 0.0 would share a text. A field whose arrays keep changing (more
    distinct arrays than hits after LIMIT of them) stops remembering.
    """

    LIMIT = 64

    def __init__(self, unpack: Callable) -> None:
        self.unpack = unpack
        self.seen: dict[bytes, str] = {}
        self.hits = 0
        self.on = True

    def text(self, data: bytes) -> str:
        if self.on:
            text = self.seen.get(data)
            if text is not None:
                self.hits += 1
                return text
        text = numbers(self.unpack(data))
        if self.on:
            self.seen[data] = text
            if len(self.seen) >= self.LIMIT:
                self.on = self.hits >= self.LIMIT
                self.seen.clear()
                self.hits = 0
        return text


def bools(data: bytes) -> str:
    """A JSON array of bools, one per byte (any non-zero byte is true, as numpy reads it)."""
    return "[" + ", ".join(["true" if b else "false" for b in data]) + "]"


def b64(data: bytes) -> str:
    """Byte arrays (`uint8[]`, `char[]`, `int8[]`) as ros.py writes them: base64 in quotes."""
    return '"' + base64.b64encode(data).decode("ascii") + '"'


def take(raw: bytes, pos: int, size: int) -> bytes:
    """`size` bytes at `pos`; numpy.frombuffer in rosbags refuses a short buffer too."""
    end = pos + size
    if end > len(raw):
        raise ValueError(f"{size} bytes at offset {pos} run past the end of the message ({len(raw)} bytes)")
    return raw[pos:end]


def ros1_string(raw: bytes, pos: int, u32: Callable) -> tuple[str, int]:
    """A ROS 1 string (uint32 length, UTF-8 bytes) as JSON text, and the position after it."""
    size = u32(raw, pos)[0]
    end = pos + 4 + size
    if end > len(raw):  # rosbags' check_string(cdr=False)
        raise ValueError(f"invalid string length {size} at offset {pos}")
    return json_string(raw[pos + 4 : end].decode()), end


def cdr_string(raw: bytes, pos: int, u32: Callable) -> tuple[str, int]:
    """A CDR string (uint32 length counting a final NUL, UTF-8 bytes, NUL) as JSON text."""
    size = u32(raw, pos)[0]
    end = pos + 4 + size
    if size < 1 or end > len(raw):  # rosbags' check_string(cdr=True)
        raise ValueError(f"invalid string length {size} at offset {pos}")
    if raw[end - 1] != 0:
        raise ValueError(f"missing string terminator at offset {end - 1}")
    return json_string(raw[pos + 4 : end - 1].decode()), end


def count(raw: bytes, pos: int, u32: Callable, minimum: int, maximum: int) -> tuple[int, int]:
    """A sequence's element count and the position after it; rosbags' check_sequence."""
    size = u32(raw, pos)[0]
    pos += 4
    if pos + size * minimum > len(raw) or size > maximum:
        raise ValueError(f"invalid sequence length {size} at offset {pos}")
    return size, pos


def strings(raw: bytes, pos: int, size: int, u32: Callable, cdr: bool, every: bool) -> tuple[str, int]:
    """`size` strings as a JSON array. In CDR, rosbags aligns to 4 bytes before every
    string of a sequence (`every`), and before every string of an array but the first."""
    items = []
    read = cdr_string if cdr else ros1_string
    for i in range(size):
        if cdr and (i or every):
            pos = (pos + 3) & -4
        text, pos = read(raw, pos, u32)
        items.append(text)
    return "[" + ", ".join(items) + "]", pos


def messages(element: Callable, raw: bytes, pos: int, size: int, align: int, path: str) -> tuple[str, int]:
    """`size` messages as a JSON array, `element` formatting each; `align` > 1 aligns
    before each (CDR). An error inside names the element: `transforms[3].header`."""
    items = []
    for i in range(size):
        if align > 1:
            pos = (pos + align - 1) & -align
        try:
            text, pos = element(raw, pos)
        except WireError as err:
            raise err.inside(f"{path}[{i}]") from None
        items.append(text)
    return "[" + ", ".join(items) + "]", pos


# What generated code finds in its globals besides its own constants.
RUNTIME = {
    "Struct": struct.Struct, "ArrayMemo": ArrayMemo, "unpack_from": struct.unpack_from, "WireError": WireError,
    "number_texts": number_texts, "numbers": numbers,
    "bools": bools, "b64": b64, "take": take, "json_string": json_string, "ros1_string": ros1_string,
    "cdr_string": cdr_string, "count": count, "strings": strings, "messages": messages,
}  # fmt: skip


class WireFormatter:
    """Formatters of the message types of one type store, for ROS 1 or CDR bytes.

    `get(msgtype)` is a function: serialized bytes -> (JSON text, header stamp in ns or
    None), generated the first time, or None when this module cannot format the type
    (then use rosbags and `ros.MessageConverter`). A bag's type store is its own, so each
    reader holds its own formatter.
    """

    def __init__(self, typestore: Any, *, cdr: bool) -> None:
        self.typestore = typestore
        self.cdr = cdr
        self._made: dict[str, Format | None] = {}

    def get(self, msgtype: str) -> Format | None:
        if msgtype not in self._made:
            self._made[msgtype] = self._make(msgtype)
        return self._made[msgtype]

    def format(self, msgtype: str, raw: bytes) -> tuple[str, int | None] | None:
        """(JSON text, header stamp or None) of one message through the type's formatter, or
        None when there is none or it refuses the bytes: then the caller reads them with
        rosbags (`deserialize`), whose error, if any, is the one to report."""
        if (fmt := self.get(msgtype)) is not None:
            try:
                return fmt(raw)
            except WireError:
                pass
        return None

    def deserialize(self, msgtype: str, raw: bytes) -> Any:
        """The message as rosbags' object, the slow path `format` falls back to."""
        store = self.typestore
        return store.deserialize_cdr(raw, msgtype) if self.cdr else store.deserialize_ros1(raw, msgtype)

    def _make(self, msgtype: str) -> Format | None:
        try:
            if not self.cdr:
                return _compile(module_source(self.typestore, msgtype, "ros1"))
            le = _compile(module_source(self.typestore, msgtype, "le"))
            be = _compile(module_source(self.typestore, msgtype, "be"))
        except Unsupported:
            return None
        except Exception:  # noqa: BLE001 - a type the generator chokes on still records, the slow way
            return None

        def cdr_message(raw: bytes) -> tuple[str, int | None]:
            # rosbags' deserialize_cdr: a 4-byte header whose second byte is the endianness.
            if len(raw) < 4 or raw[0] != 0 or raw[1] > 1:
                raise WireError("", "invalid or unsupported CDR encapsulation")
            return (le if raw[1] else be)(raw)

        return cdr_message


def _compile(source: str) -> Format:
    namespace = dict(RUNTIME)
    exec(compile(source, "<roswire generated>", "exec"), namespace)  # noqa: S102 (our own generated source)
    return namespace["message"]


def formatter_source(typestore: Any, msgtype: str, wire: str = "ros1") -> str:
    """The generated source for `msgtype` (`wire`: "ros1", or "le"/"be" for CDR)."""
    return module_source(typestore, msgtype, wire)


def main(argv: list[str]) -> int:
    """python -m cclogfs.jsontext.roswire BAG TYPE: print the formatter of TYPE in BAG."""
    from pathlib import Path

    from rosbags.highlevel import AnyReader

    with AnyReader([Path(argv[0])]) as reader:
        print(formatter_source(reader.typestore, argv[1], "le" if reader.is2 else "ros1"))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
