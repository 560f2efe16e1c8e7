"""ROS messages to JSON the way rosbridge writes them.

- fields in message-definition order (rosbags messages are dataclasses in that order);
  the definition's constants (`STATUS_NO_FIX = -1` in NavSatStatus) are not fields of a
  message and are left out, as rosbridge leaves them out;
- `builtin_interfaces/Time` and `Duration` as `{"sec": .., "nanosec": ..}` (ROS 1 bags,
  whose times have `secs/nsecs`, come through rosbags as the same ROS 2 types);
- `uint8[]`/`char[]` byte arrays as base64 strings, other arrays as JSON arrays;
- floats as Python's `repr` (what `json.dumps` writes), NaN and infinities as `NaN`,
  `Infinity`, `-Infinity` (what Python's json, and so rosbridge, writes);
- the text is `json.dumps(obj)` with its default separators.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import keyword
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["MessageConverter", "message_fields", "message_stamp_ns", "message_to_dict", "message_to_json"]

_BYTE_DTYPES = (np.uint8, np.int8)
# Field annotations whose values json.dumps takes as they are.
_SCALARS = {"int", "float", "str", "bool"}


def message_fields(cls: type) -> list[dataclasses.Field] | None:
    """The fields of a rosbags message class in definition order, or None if it is not one.

    rosbags declares the definition's constants and `__msgtype__` as dataclass fields with
    a default value; a message's own fields have none.
    """
    if not dataclasses.is_dataclass(cls):
        return None
    return [f for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING and not f.name.startswith("__")]


class MessageConverter:
    """Turns rosbags messages into rosbridge JSON with one generated builder per class.

    The builder of a class is a single dict expression, compiled from the class's fields
    the first time a message of it is seen: scalars are read as they are, nested messages
    are inlined (`m.pose.pose.position.x`), numeric arrays become lists, and anything else
    (lists of messages, say) goes through `to_dict`. Walking the fields of every message
    instead (a call and type tests per value) took most of the time of reading a bag; the
    text is still `json.dumps` of the same dict. Builders live in the converter, not
    globally: every bag reader builds its own message classes.
    """

    def __init__(self) -> None:
        self._builders: dict[type, Callable[[Any], dict] | None] = {}

    def to_json(self, msg: Any) -> str:
        return json.dumps(self.to_dict(msg))

    def to_dict(self, value: Any) -> Any:
        """A message (or field value) as plain JSON-able Python objects."""
        cls = value.__class__
        try:
            builder = self._builders[cls]
        except KeyError:
            builder = self._builders[cls] = self._compile(value)
        return value_to_dict(value, self.to_dict) if builder is None else builder(value)

    def _compile(self, sample: Any) -> Callable[[Any], dict] | None:
        """The builder of sample's class, or None when it is not a message."""
        if message_fields(sample.__class__) is None:
            return None
        source = "lambda m: " + _dict_expr(sample, "m")
        return eval(source, {"to_dict": self.to_dict, "array": _array, "getattr": getattr})  # noqa: S307


def _dict_expr(sample: Any, path: str) -> str:
    """A dict display building the message at `path`, shaped after `sample`.

    A field's message type is fixed by its definition, so the sample's nested messages
    tell the classes of every message of this class.
    """
    items = []
    for f in message_fields(sample.__class__) or ():
        attr = f"{path}.{f.name}" if f.name.isidentifier() and not keyword.iskeyword(f.name) else \
            f"getattr({path}, {f.name!r})"  # fmt: skip
        value = getattr(sample, f.name)
        if f.type in _SCALARS:  # rosbags' annotation of int, float, str and bool fields
            expr = attr
        elif f.type.startswith("np.ndarray"):
            expr = f"array({attr})"
        elif message_fields(value.__class__) is not None:
            expr = _dict_expr(value, attr)
        else:
            expr = f"to_dict({attr})"
        items.append(f"{f.name!r}: {expr}")
    return "{" + ", ".join(items) + "}"


def _array(value: Any) -> Any:
    """A numeric array field: a list, or base64 text for bytes (uint8[], char[])."""
    if isinstance(value, np.ndarray):
        if value.dtype in _BYTE_DTYPES:
            return base64.b64encode(value.tobytes()).decode("ascii")
        return value.tolist()
    return value_to_dict(value, _array)


def value_to_dict(value: Any, to_dict: Callable[[Any], Any]) -> Any:
    """A field value that is not a message, with `to_dict` for the messages inside it."""
    cls = value.__class__
    if cls is float or cls is int or cls is str or cls is bool:
        return value
    if isinstance(value, np.ndarray):
        if value.dtype in _BYTE_DTYPES:
            return base64.b64encode(value.tobytes()).decode("ascii")
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [to_dict(v) for v in value]
    if isinstance(value, (bytes, bytearray)):
        return base64.b64encode(bytes(value)).decode("ascii")
    if isinstance(value, np.generic):
        return value.item()
    return value


def message_to_dict(msg: Any) -> Any:
    """A rosbags message (or field value) as plain JSON-able Python objects."""
    return MessageConverter().to_dict(msg)


def message_to_json(msg: Any) -> str:
    """The rosbridge JSON text of a rosbags message (for many messages, reuse a MessageConverter)."""
    return MessageConverter().to_json(msg)


def message_stamp_ns(msg: Any) -> int | None:
    """`header.stamp` in nanoseconds, or None when the message has no header stamp."""
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None or not hasattr(stamp, "sec"):
        return None
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
