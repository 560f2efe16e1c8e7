"""ROS messages to JSON the way rosbridge writes them.

- fields in message-definition order (rosbags messages are dataclasses in that order);
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
from typing import Any

import numpy as np

__all__ = ["message_stamp_ns", "message_to_dict", "message_to_json"]

_BYTE_DTYPES = (np.uint8, np.int8)


def message_to_dict(msg: Any) -> Any:
    """A rosbags message (or field value) as plain JSON-able Python objects."""
    if dataclasses.is_dataclass(msg):
        return {
            f.name: message_to_dict(getattr(msg, f.name))
            for f in dataclasses.fields(msg)
            if not f.name.startswith("__")
        }
    if isinstance(msg, np.ndarray):
        if msg.dtype in _BYTE_DTYPES:
            return base64.b64encode(msg.tobytes()).decode("ascii")
        return msg.tolist()
    if isinstance(msg, (list, tuple)):
        return [message_to_dict(v) for v in msg]
    if isinstance(msg, (bytes, bytearray)):
        return base64.b64encode(bytes(msg)).decode("ascii")
    if isinstance(msg, np.generic):
        return msg.item()
    return msg


def message_to_json(msg: Any) -> str:
    """The rosbridge JSON text of a rosbags message."""
    return json.dumps(message_to_dict(msg))


def message_stamp_ns(msg: Any) -> int | None:
    """`header.stamp` in nanoseconds, or None when the message has no header stamp."""
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None or not hasattr(stamp, "sec"):
        return None
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
