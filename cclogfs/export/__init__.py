"""Exports of stored windows to formats other tools read: MCAP (JSON), Parquet, JSONL.

Exporters take any iterable of windows (`StoredWindow`: what the store's `query()` returns)
and know nothing of how they were chosen or stored.
"""

from __future__ import annotations

from .base import ExportStats, Progress, StoredWindow
from .jsonl import merged_messages, write_jsonl
from .jsonschema import message_schema, schema_of
from .mcap import WINDOW_METADATA, export_mcap
from .parquet import export_parquet, flatten

__all__ = [
    "WINDOW_METADATA",
    "ExportStats",
    "Progress",
    "StoredWindow",
    "export_mcap",
    "export_parquet",
    "flatten",
    "merged_messages",
    "message_schema",
    "schema_of",
    "write_jsonl",
]
