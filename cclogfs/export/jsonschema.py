"""A JSON Schema describing the shape of one message, for MCAP's "jsonschema" encoding.

It describes rather than restricts (no `required`, extra properties allowed), because it
is derived from one message and later messages of the stream may carry more fields.
"""

from __future__ import annotations

import json
from typing import Any


# Deeper than this, a value is described as {} (any JSON): a store takes messages nested as
# deep as Python's json reads (~900 levels), and describing each level took two Python
# frames, so exporting one ended in a RecursionError traceback.
MAX_DEPTH = 64


def schema_of(value: Any, depth: int = 0) -> dict[str, Any]:
    """The JSON Schema of a parsed JSON value's shape (numbers are "number", ints included)."""
    if depth >= MAX_DEPTH:
        return {}
    if isinstance(value, dict):
        return {"type": "object", "properties": {k: schema_of(v, depth + 1) for k, v in value.items()}}
    if isinstance(value, list):
        return {"type": "array", "items": schema_of(value[0], depth + 1)} if value else {"type": "array"}
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, (int, float)):
        return {"type": "number"}
    if isinstance(value, str):
        return {"type": "string"}
    return {}


def message_schema(text: str, title: str) -> bytes:
    """The schema document (UTF-8 JSON) for a stream whose first message is `text`."""
    doc = {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title}
    doc.update(schema_of(json.loads(text)))
    return json.dumps(doc).encode("utf-8")
