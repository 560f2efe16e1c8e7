"""`rosjson.message_to_json` with the per-class field lookups cached.

`dataclasses.fields()` on every nested message dominated bag reading (2.5x slower
than this); the output is the same text, checked against `rosjson` on every message
of the shared data in tests/test_ingest_convert.py.
"""

from __future__ import annotations

import base64
import dataclasses
import json
from typing import Any

import numpy as np

from ..rosjson import _BYTE_DTYPES


class MessageConverter:
    """Turns rosbags messages into rosbridge JSON; keeps one field list per message class."""

    def __init__(self) -> None:
        # Keyed per converter, not globally: every bag reader builds its own classes.
        self._fields: dict[type, tuple[str, ...] | None] = {}

    def to_json(self, msg: Any) -> str:
        """The same text as `cclogfs.rosjson.message_to_json(msg)`."""
        return json.dumps(self.to_dict(msg))

    def to_dict(self, value: Any) -> Any:
        """The same objects as `cclogfs.rosjson.message_to_dict(value)`."""
        cls = value.__class__
        try:
            names = self._fields[cls]
        except KeyError:
            names = self._fields[cls] = self._names(cls)
        if names is not None:
            to_dict = self.to_dict
            return {n: to_dict(getattr(value, n)) for n in names}
        if cls is float or cls is int or cls is str or cls is bool:
            return value
        if isinstance(value, np.ndarray):
            if value.dtype in _BYTE_DTYPES:
                return base64.b64encode(value.tobytes()).decode("ascii")
            return value.tolist()
        if isinstance(value, (list, tuple)):
            return [self.to_dict(v) for v in value]
        if isinstance(value, (bytes, bytearray)):
            return base64.b64encode(bytes(value)).decode("ascii")
        if isinstance(value, np.generic):
            return value.item()
        return value

    @staticmethod
    def _names(cls: type) -> tuple[str, ...] | None:
        if not dataclasses.is_dataclass(cls):
            return None
        return tuple(f.name for f in dataclasses.fields(cls) if not f.name.startswith("__"))
