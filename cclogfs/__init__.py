"""cclogfs: a storage engine for robot sensor logs.

Open a store with `open_store`, add windows with `Store.put_window`, read them back with
`Store.query`. The on-disk format and durability contract are in docs/FORMAT.md.
"""

from .errors import (
    CclogError,
    CodecError,
    CorruptionError,
    InvalidInputError,
    ModelError,
    SourceError,
    StoreError,
    StoreFailedError,
    StoreLockedError,
    UnknownCodecError,
)

__version__ = "0.1.0"

# The store is imported on first use, so `import cclogfs.classifier` does not load the
# storage engine (the classifier must stay independent of it, and tests check that).
_STORE_NAMES = ("Dropped", "Receipt", "Recovery", "Replacement", "RewriteReport", "Store", "Window", "open_store")


def __getattr__(name: str):
    if name in _STORE_NAMES:
        from . import store

        return getattr(store, name)
    raise AttributeError(f"module 'cclogfs' has no attribute {name!r}")


__all__ = [
    "CclogError",
    "CodecError",
    "CorruptionError",
    "Dropped",
    "InvalidInputError",
    "ModelError",
    "Receipt",
    "Recovery",
    "Replacement",
    "RewriteReport",
    "SourceError",
    "Store",
    "StoreError",
    "StoreFailedError",
    "StoreLockedError",
    "UnknownCodecError",
    "Window",
    "open_store",
]
