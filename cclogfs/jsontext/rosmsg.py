"""Rosbridge JSON back into rosbags messages, so a stored message can be serialized again
(ROS 1 for `cclog play --to ros1://`, CDR for ROS 2): the inverse of `jsontext.ros`.

Fields are filled from the type's definition in a rosbags type store; a field the JSON
lacks gets its zero value (a ROS 2 header has no `seq`: it becomes 0 in ROS 1), a key the
type lacks is an error unless `drop` (given the key's path, the type and the key) accepts
to leave it out: the CDR export drops a ROS 1 `header.seq` so, and counts it. Byte arrays come as base64 (as jsontext.ros writes them), other
primitive arrays as numpy arrays, which is what rosbags' serializers take.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from rosbags.typesys.base import Nodetype

from ..errors import InvalidInputError

# rosbags' base type names -> numpy dtypes of the arrays it (de)serializes.
_DTYPES = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "octet": np.uint8, "int8": np.int8,
           "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
           "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64}  # fmt: skip
_BASE64 = (np.uint8, np.int8)
# Base types whose JSON value of this Python class is taken as it is (integers are checked by _base).
_PLAIN = {"float64": float, "string": str, "wstring": str}
_FLOAT32_MAX = float(np.finfo(np.float32).max)


def from_json(typestore: Any, msgtype: str, text: str) -> Any:
    """The rosbags message of type `msgtype` that `text` (rosbridge JSON) describes."""
    return build(typestore, msgtype, json.loads(text))


# (path of a key, its message type, the key) -> True to leave the key out, False to refuse it.
Drop = Callable[[str, str, str], bool]


def build(typestore: Any, msgtype: str, obj: Any, where: str = "", drop: Drop | None = None) -> Any:
    """A `msgtype` message from a JSON object (a dict; None gives every field's zero)."""
    where = where or msgtype
    if obj is None:
        obj = {}
    if not isinstance(obj, dict):
        raise InvalidInputError(f"{where}: expected a JSON object for {msgtype}, got {type(obj).__name__}")
    try:
        _, fields = typestore.fielddefs[msgtype]
    except KeyError:
        raise InvalidInputError(f"{where}: the message type {msgtype} is not known") from None
    if len(obj) > len(fields) or any(key not in obj for key, _ in fields):  # else the keys are the fields
        names = {name for name, _ in fields}
        for key in sorted(set(obj) - names):
            if drop is None or not drop(f"{where}.{key}", msgtype, key):
                raise InvalidInputError(f"{where}: {msgtype} has no field {key!r}")
    values = {}
    for name, desc in fields:
        value = obj.get(name)
        kind, detail = desc
        # The common case without a call: a float or string the JSON already has right.
        if kind == Nodetype.BASE and value.__class__ is _PLAIN.get(detail[0]):
            values[name] = value
        else:
            values[name] = _value(typestore, desc, value, f"{where}.{name}", drop)
    return typestore.types[msgtype](**values)


def _value(typestore: Any, desc: tuple, value: Any, where: str, drop: Drop | None) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        return _base(detail[0], value, where)
    if kind == Nodetype.NAME:
        return build(typestore, detail, value, where, drop)
    (sub_kind, sub_detail), length = detail
    if sub_kind == Nodetype.BASE and sub_detail[0] in _DTYPES:
        arr = _array(_DTYPES[sub_detail[0]], value, where)
        if kind == Nodetype.ARRAY and value is None:
            arr = np.zeros(length, dtype=arr.dtype)
    else:
        sub = (sub_kind, sub_detail)
        arr = [_value(typestore, sub, v, f"{where}[{i}]", drop) for i, v in enumerate(value or [])]
        if kind == Nodetype.ARRAY and value is None:
            arr = [_value(typestore, sub, None, where, drop) for _ in range(length)]
    if kind == Nodetype.ARRAY and len(arr) != length:
        raise InvalidInputError(f"{where}: expected {length} elements, got {len(arr)}")
    return arr


def _array(dtype: Any, value: Any, where: str) -> np.ndarray:
    if value is None:
        return np.zeros(0, dtype=dtype)
    if isinstance(value, str):  # base64, as jsontext.ros writes byte arrays
        if dtype not in _BASE64:
            raise InvalidInputError(f"{where}: a base64 string for a {np.dtype(dtype).name} array")
        return np.frombuffer(base64.b64decode(value), dtype=dtype).copy()
    try:
        return np.array(value, dtype=dtype)
    except (TypeError, ValueError, OverflowError) as err:
        raise InvalidInputError(f"{where}: not an array of {np.dtype(dtype).name}: {err}") from None


def _base(typename: str, value: Any, where: str) -> Any:
    if typename == "string" or typename == "wstring":
        if value is None:
            return ""
        if not isinstance(value, str):
            raise InvalidInputError(f"{where}: expected a string")
        return value
    if value is None:
        return False if typename == "bool" else 0.0 if typename.startswith("float") else 0
    if typename == "bool":
        if isinstance(value, bool) or value in (0, 1):  # `"no"` is not true
            return bool(value)
    elif typename.startswith("float"):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = float(value)
            if typename == "float32" and _FLOAT32_MAX < abs(value) < math.inf:
                raise InvalidInputError(f"{where}: {value!r} is out of range for a float32")
            return value
    elif isinstance(value, int) and not isinstance(value, bool):
        info = np.iinfo(_DTYPES[typename])
        if info.min <= value <= info.max:
            return value
        raise InvalidInputError(f"{where}: {value} is out of range for a {typename} ({info.min} to {info.max})")
    raise InvalidInputError(f"{where}: {value!r} is not a {typename}")
