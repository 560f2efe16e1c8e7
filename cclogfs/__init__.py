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
from .store import Receipt, Recovery, Store, Window, open_store

__version__ = "0.1.0"

__all__ = [
    "CclogError",
    "CodecError",
    "CorruptionError",
    "InvalidInputError",
    "ModelError",
    "Receipt",
    "Recovery",
    "SourceError",
    "Store",
    "StoreError",
    "StoreFailedError",
    "StoreLockedError",
    "UnknownCodecError",
    "Window",
    "open_store",
]
