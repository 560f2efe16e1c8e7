"""A FileSystem that fails one chosen operation, as a failing disk would.

`FaultyFileSystem(at=N, mode=M)` passes every call to the real file system except the N-th
counted operation (1-based), which fails with mode M:

- `eio`: OSError EIO (any operation: a read, a write, a rename, a directory fsync...)
- `enospc`: OSError ENOSPC (operations that may need space: create, write, truncate,
  mkdir, rename, lock, allocate, fsync, for delayed allocation fails there)
- `short`: a write that lands only its first half, then ENOSPC (a disk filling mid-write)
- `fsync`: an fsync (of a file or a directory) that fails with EIO

Only that one operation fails; everything after it works again, so a test sees what the
one failure did. Each failure passes through `io_op`, as an OSError of the real calls
does. Operations count from `arm()`; `ops` lists what ran since (kind, file), so
a dry run with `at=0` tells a test how many operations there are and which modes apply.
"""

from __future__ import annotations

import errno
import os
from dataclasses import dataclass, field

from cclogfs.store.fs import FileSystem, io_op

# Which modes apply to which operation.
MODES = {
    "open": ("eio",),
    "create": ("eio", "enospc"),
    "pread": ("eio",),
    "pwrite": ("eio", "enospc", "short"),
    "fsync": ("eio", "enospc", "fsync"),
    "truncate": ("eio", "enospc"),
    "rename": ("eio", "enospc"),
    "unlink": ("eio",),
    "fsync_dir": ("eio", "fsync"),
    "listdir": ("eio",),
    "mkdir": ("eio", "enospc"),
    "lock": ("eio", "enospc"),
    "allocate": ("eio", "enospc"),
}


@dataclass
class FaultyFileSystem(FileSystem):
    at: int = 0  # the operation that fails (1-based); 0: none
    mode: str = "eio"
    count: int = 0
    ops: list[tuple[str, str]] = field(default_factory=list)
    fired: tuple[str, str, str] | None = None  # (operation, path, mode) of the injected fault
    armed: bool = False  # operations count (and fail) only once armed

    def arm(self) -> None:
        """Count from here: the operation under test starts."""
        self.armed, self.count, self.ops = True, 0, []

    @property
    def armed_ops(self) -> list[tuple[str, str]]:
        return self.ops

    def _step(self, kind: str, path: str) -> bool:
        """Count an operation; True when it is the one to fail (the caller then fails it)."""
        if not self.armed:
            return False
        self.count += 1
        self.ops.append((kind, os.path.basename(path)))
        if self.count != self.at:
            return False
        mode = self.mode if self.mode in MODES[kind] else "eio"
        self.fired = (kind, os.path.basename(path), mode)
        return True

    def _fail(self, path: str) -> None:
        assert self.fired is not None
        code = errno.ENOSPC if self.fired[2] in ("enospc", "short") else errno.EIO
        raise OSError(code, f"{os.strerror(code)} (injected)", path)

    @io_op("opening")
    def open(self, path: str, *, write: bool = False, create: bool = False) -> int:
        if self._step("create" if create else "open", path):
            self._fail(path)
        return super().open(path, write=write, create=create)

    @io_op("reading")
    def pread(self, fd: int, size: int, offset: int) -> bytes:
        path = self.name_of(fd)
        if self._step("pread", path):
            self._fail(path)
        return super().pread(fd, size, offset)

    @io_op("writing")
    def pwrite(self, fd: int, data: bytes, offset: int) -> None:
        path = self.name_of(fd)
        if self._step("pwrite", path):
            if self.fired[2] == "short" and len(data) > 1:
                super().pwrite(fd, bytes(data[: len(data) // 2]), offset)
            self._fail(path)
        super().pwrite(fd, data, offset)

    @io_op("fsync")
    def fsync(self, fd: int) -> None:
        path = self.name_of(fd)
        if self._step("fsync", path):
            self._fail(path)
        super().fsync(fd)

    @io_op("truncating")
    def truncate(self, fd: int, size: int) -> None:
        path = self.name_of(fd)
        if self._step("truncate", path):
            self._fail(path)
        super().truncate(fd, size)

    @io_op("allocating")
    def allocate(self, fd: int, size: int) -> None:
        path = self.name_of(fd)
        if self._step("allocate", path):
            self._fail(path)
        super().allocate(fd, size)

    @io_op("renaming")
    def rename(self, src: str, dst: str) -> None:
        if self._step("rename", dst):
            self._fail(dst)
        super().rename(src, dst)

    @io_op("removing")
    def unlink(self, path: str) -> None:
        if self._step("unlink", path):
            self._fail(path)
        super().unlink(path)

    @io_op("fsync of the directory")
    def fsync_dir(self, path: str) -> None:
        if self._step("fsync_dir", path):
            self._fail(path)
        super().fsync_dir(path)

    @io_op("listing")
    def listdir(self, path: str) -> list[str]:
        if self._step("listdir", path):
            self._fail(path)
        return super().listdir(path)

    @io_op("making the directory")
    def mkdir(self, path: str) -> None:
        if self._step("mkdir", path):
            self._fail(path)
        super().mkdir(path)

    @io_op("locking")
    def lock(self, path: str) -> int | None:
        if self._step("lock", path):
            self._fail(path)
        return super().lock(path)
