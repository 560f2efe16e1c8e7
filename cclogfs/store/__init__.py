"""The storage engine: a flat-namespace append log of compressed, checksummed windows.

Knows nothing of classifiers, ingest, export, upkeep or the CLI (tests/test_layering.py
checks it). Layers, each importing only those before it:

    format, fs          the bytes on disk (mirror of docs/FORMAT.md) and the one I/O layer
    records             the one reader and checker of the record at an offset
    index, segment      a segment's time index; a segment file, its append buffer and scan
    manifest            the manifest as versions (the store's catalogue)
    check, encode       checks on what is put; a window turned into a record
    window, recovery    what a query returns; opening segments and repairing the tail
    compaction          rewrite and retention (the store passes itself in)
    store               `Store` and `open_store`
    fsck                the checker, on the store's public API
    rebuild, repair     `fsck --repair`: a damaged manifest rebuilt; indexes, salvage, quarantine
"""

from importlib import import_module

# Exported lazily (PEP 562), so that importing one module of the package (the codecs read
# `format`) does not load the whole engine.
_HOME = {
    "Dropped": "compaction", "Replacement": "compaction", "RewriteReport": "compaction",
    "file_bytes": "compaction", "Reason": "format", "RecordFlag": "format", "Finding": "fsck",
    "FsckReport": "fsck", "check_store": "fsck", "RepairReport": "repair", "repair_store": "repair", "merge_stream_stats": "index",
    "SealedSegment": "manifest", "Recovery": "recovery", "Store": "store", "open_store": "store",
    "Receipt": "window", "Window": "window",
}  # fmt: skip


def __getattr__(name: str):
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'cclogfs.store' has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{home}"), name)


__all__ = [
    "Dropped",
    "Finding",
    "FsckReport",
    "Reason",
    "Receipt",
    "RecordFlag",
    "RepairReport",
    "Recovery",
    "Replacement",
    "RewriteReport",
    "SealedSegment",
    "Store",
    "Window",
    "check_store",
    "file_bytes",
    "merge_stream_stats",
    "open_store",
    "repair_store",
]
