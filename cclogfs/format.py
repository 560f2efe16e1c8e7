"""Mirror of docs/FORMAT.md: every number the on-disk format defines lives here."""

from __future__ import annotations

from enum import IntEnum


class CodecId(IntEnum):
    """Codec numbers stored in record headers. 0 is invalid; values never change."""

    NONE = 1
    ZSTD = 2
    LZMA = 3
    COLUMNAR = 4
