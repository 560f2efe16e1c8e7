"""Rosbridge JSON back into rosbags messages, so a stored message can be serialized again
(ROS 1 for `cclog play --to ros1://`, CDR for ROS 2): the inverse of `jsontext.ros`.

Fields are filled from the type's definition in a rosbags type store; a field the JSON
lacks gets its zero value (a ROS 2 header has no `seq`: it becomes 0 in ROS 1), a key the
type lacks is an error. Byte arrays come as base64 (as jsontext.ros writes them), other
primitive arrays as numpy arrays, which is what rosbags' serializers take.
"""

from __future__ import annotations

import base64
import json
from typing import Any

import numpy as np
from rosbags.typesys.base import Nodetype

from ..errors import InvalidInputError

# rosbags' base type names -> numpy dtypes of the arrays it (de)serializes.
_DTYPES = {"bool": np.bool_, "byte": np.uint8, "char": np.uint8, "octet": np.uint8, "int8": np.int8,
           "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32,
           "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64}  # fmt: skip
_BASE64 = (np.uint8, np.int8)


def from_json(typestore: Any, msgtype: str, text: str) -> Any:
    """The rosbags message of type `msgtype` that `text` (rosbridge JSON) describes."""
    return build(typestore, msgtype, json.loads(text))


def build(typestore: Any, msgtype: str, obj: Any, where: str = "") -> Any:
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
    names = {name for name, _ in fields}
    if extra := sorted(set(obj) - names):
        raise InvalidInputError(f"{where}: {msgtype} has no field {extra[0]!r}")
    values = {name: _value(typestore, desc, obj.get(name), f"{where}.{name}") for name, desc in fields}
    return typestore.types[msgtype](**values)


def _value(typestore: Any, desc: tuple, value: Any, where: str) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        return _base(detail[0], value, where)
    if kind == Nodetype.NAME:
        return build(typestore, detail, value, where)
    (sub_kind, sub_detail), length = detail
    if sub_kind == Nodetype.BASE and sub_detail[0] in _DTYPES:
        arr = _array(_DTYPES[sub_detail[0]], value, where)
        if kind == Nodetype.ARRAY and value is None:
            arr = np.zeros(length, dtype=arr.dtype)
    else:
        arr = [_value(typestore, (sub_kind, sub_detail), v, f"{where}[{i}]") for i, v in enumerate(value or [])]
        if kind == Nodetype.ARRAY and value is None:
            arr = [_value(typestore, (sub_kind, sub_detail), None, where) for _ in range(length)]
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
        return bool(value)
    if typename.startswith("float"):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif isinstance(value, int) and not isinstance(value, bool):
        return value
    raise InvalidInputError(f"{where}: {value!r} is not a {typename}")
