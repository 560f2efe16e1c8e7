"""Exports of stored windows to formats other tools read: MCAP (ROS 2 CDR or JSON), rosbag2,
Parquet, JSONL.

Exporters take any iterable of windows (`StoredWindow`: what the store's `query()` returns)
and know nothing of how they were chosen or stored.

Each name is imported from its module on first use: `cclog cat` needs only the JSONL
writer, and importing pyarrow for Parquet took longer than the rest of a short `cat`.
"""

from __future__ import annotations

from importlib import import_module

# name -> the module of this package that defines it
_MODULES = {
    "Clip": "base",
    "ExportStats": "base",
    "Progress": "base",
    "StoredWindow": "base",
    "merged_messages": "jsonl",
    "write_jsonl": "jsonl",
    "message_schema": "jsonschema",
    "schema_of": "jsonschema",
    "WINDOW_METADATA": "mcap",
    "export_mcap": "mcap",
    "McapStats": "mcap",
    "export_rosbag2": "rosbag2",
    "export_parquet": "parquet",
    "flatten": "parquet",
}

__all__ = sorted(_MODULES)


def __getattr__(name: str):
    if name in _MODULES:
        return getattr(import_module(f".{_MODULES[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
