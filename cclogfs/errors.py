"""One exception tree for cclogfs: every error a user can see derives from CclogError.

Messages are whole sentences that name the file, the offset or the field at fault.
"""

from __future__ import annotations


class CclogError(Exception):
    """Base class of every cclogfs error."""


class InvalidInputError(CclogError, ValueError):
    """Input handed to cclogfs is malformed (bad JSON, bad stream name, times out of order...)."""


class StoreError(CclogError):
    """The store cannot do what was asked (missing, locked, closed, failed)."""


class StoreLockedError(StoreError):
    """Another writer holds the store's lock."""


class StoreIOError(StoreError, OSError):
    """A file operation of the store failed (EIO, ENOSPC, EROFS, EACCES, ...). Also an
    OSError, so the store's failure handling treats it as one; a CclogError, so no caller
    ever sees a raw OSError. `what` names the operation."""

    def __init__(self, errno: int, strerror: str, filename: str, what: str):
        super().__init__(errno, strerror, filename)
        self.what = what

    def __str__(self) -> str:
        return f"{self.filename}: {self.what} failed: {self.strerror}"


class StoreFailedError(StoreError):
    """An fsync or write failed; the store refuses further writes until reopened."""


class CorruptionError(CclogError):
    """Stored bytes fail a check (checksum, length, magic, framing).

    `path`, `offset` and `reason` say where and why; `reason` is one of the fixed
    strings in `cclogfs.store.format.Reason`.
    """

    def __init__(self, message: str, *, path: str = "", offset: int = -1, reason: str = ""):
        super().__init__(message)
        self.path = path
        self.offset = offset
        self.reason = reason


class DamagedError(CorruptionError):
    """A read would miss windows the store knows are damaged: it refuses rather than
    answer in part. `damage` lists them; pass `skip_damaged=True` to read the rest."""

    def __init__(self, message: str, damage: list, **kwargs):
        super().__init__(message, **kwargs)
        self.damage = damage


class CodecError(CclogError):
    """A codec cannot encode or decode (unknown id, bad config, bad payload)."""


class UnknownCodecError(CodecError):
    """The codec id is not in the registry."""


class ModelError(CclogError):
    """A classifier model file is missing, malformed, or made for another configuration."""


class SourceError(CclogError):
    """A log source (bag, MCAP, JSONL) cannot be read; the message names file and position."""
