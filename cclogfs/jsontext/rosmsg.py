"""Rosbridge JSON back into rosbags messages, so a stored message can be serialized again
(ROS 1 for `cclog play --to ros1://`, CDR for ROS 2): the inverse of `jsontext.ros`.

Fields are filled from the type's definition in a rosbags type store; a field the JSON
lacks gets its zero value (a ROS 2 header has no `seq`: it becomes 0 in ROS 1), a key the
type lacks is an error. A `Fit` given to `build` may decide otherwise and is told of both:
the CDR export drops a ROS 1 `header.seq`, takes ROS 1 `CameraInfo.D` as ROS 2's `d`, and
counts what it did. Byte arrays come as base64 (as jsontext.ros writes them), other
primitive arrays as numpy arrays, which is what rosbags' serializers take.
"""

from __future__ import annotations

import base64
import json
import math
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


class Fit:
    """What to do with a JSON object whose keys are not its type's fields. This default
    refuses a key the type lacks and lets a missing field be zero."""

    def extra(self, where: str, msgtype: str, key: str, value: Any, fields: list[str]) -> str | None:
        """For a key (at path `where`) that `msgtype` lacks: None to refuse it, "" to leave it
        out, or the field (one of `fields`, absent from the object) that takes its value."""
        return None

    def missing(self, where: str, msgtype: str, field: str) -> None:
        """A field the object lacks (at path `where`), which becomes zero."""


_REFUSE = Fit()


def build(typestore: Any, msgtype: str, obj: Any, where: str = "", fit: Fit = _REFUSE) -> Any:
    """A `msgtype` message from a JSON object (a dict; None gives every field's zero)."""
    where = where or msgtype
    absent = obj is None
    if absent:
        obj = {}
    if not isinstance(obj, dict):
        raise InvalidInputError(f"{where}: expected a JSON object for {msgtype}, got {type(obj).__name__}")
    try:
        _, fields = typestore.fielddefs[msgtype]
    except KeyError:
        raise InvalidInputError(f"{where}: the message type {msgtype} is not known") from None
    if len(obj) > len(fields) or any(key not in obj for key, _ in fields):  # else the keys are the fields
        obj = _fit(obj, msgtype, [name for name, _ in fields], where, fit, absent)
    values = {}
    for name, desc in fields:
        value = obj.get(name)
        kind, detail = desc
        # The common case without a call: a float or string the JSON already has right.
        if kind == Nodetype.BASE and value.__class__ is _PLAIN.get(detail[0]):
            values[name] = value
        elif value is None and name in obj:  # rosbridge never writes null: not silently a zero
            raise InvalidInputError(f"{where}.{name}: null is not a value of {msgtype}.{name}")
        else:
            values[name] = _value(typestore, desc, value, f"{where}.{name}", fit)
    return typestore.types[msgtype](**values)


def _fit(obj: dict, msgtype: str, names: list[str], where: str, fit: Fit, absent: bool) -> dict:
    """`obj` with the keys `fit` renames or drops handled; raises for a key it refuses."""
    out = {k: v for k, v in obj.items() if k in names}
    for key in sorted(set(obj) - set(names)):
        free = [n for n in names if n not in out]
        field = fit.extra(f"{where}.{key}", msgtype, key, obj[key], free)
        if field is None:
            raise InvalidInputError(f"{where}: {msgtype} has no field {key!r}")
        if field:
            out[field] = obj[key]
    if not absent:  # a whole message the JSON lacks is one missing field, told by its parent
        for name in names:
            if name not in out:
                fit.missing(f"{where}.{name}", msgtype, name)
    return out


def _value(typestore: Any, desc: tuple, value: Any, where: str, fit: Fit) -> Any:
    kind, detail = desc
    if kind == Nodetype.BASE:
        return _base(detail[0], value, where)
    if kind == Nodetype.NAME:
        return build(typestore, detail, value, where, fit)
    (sub_kind, sub_detail), length = detail
    if sub_kind == Nodetype.BASE and sub_detail[0] in _DTYPES:
        arr = _array(_DTYPES[sub_detail[0]], value, where)
        if kind == Nodetype.ARRAY and value is None:
            arr = np.zeros(length, dtype=arr.dtype)
    else:
        sub = (sub_kind, sub_detail)
        arr = [_value(typestore, sub, v, f"{where}[{i}]", fit) for i, v in enumerate(value or [])]
        if kind == Nodetype.ARRAY and value is None:
            arr = [_value(typestore, sub, None, where, fit) for _ in range(length)]
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
