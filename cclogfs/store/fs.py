"""The one small file-system layer every byte of store I/O goes through.

Keeping it to a few calls on file descriptors (open, pread, pwrite, fsync, truncate,
rename, unlink, fsync of a directory) lets tests record every operation and build the
disk images a crash could leave, which monkeypatching `os` cannot do for `open().write()`.
"""

from __future__ import annotations

import errno
import fcntl
import os
from dataclasses import dataclass, field
from typing import Any

from . import planted

# Permissions of what the store creates (FORMAT.md, "Permissions"): a robot's logs hold
# where people live and work, so they are the owner's alone unless a deployment changes these.
FILE_MODE = 0o600
DIR_MODE = 0o700

# Every file is opened without following a symlink in its last component: a symlink named
# like a store file must not let the writer truncate or write a file outside the store.
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def _open_nofollow(path: str, flags: int) -> int:
    try:
        return os.open(path, flags | (0 if "follow-symlink" in planted.BUGS else _NOFOLLOW), FILE_MODE)
    except OSError as err:
        if err.errno == errno.ELOOP:  # what O_NOFOLLOW gives for a symlink: say it plainly
            raise OSError(errno.ELOOP, "is a symbolic link, which the store never follows", path) from None
        raise


class FileSystem:
    """The real file system (POSIX)."""

    def open(self, path: str, *, write: bool = False, create: bool = False) -> int:
        flags = os.O_RDWR if write else os.O_RDONLY
        if create:
            flags |= os.O_CREAT | os.O_EXCL
        return _open_nofollow(path, flags)

    def close(self, fd: int) -> None:
        os.close(fd)

    def pread(self, fd: int, size: int, offset: int) -> bytes:
        chunks, got = [], 0
        while got < size:  # pread may return short reads for large sizes
            chunk = os.pread(fd, size - got, offset + got)
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        return chunks[0] if len(chunks) == 1 else b"".join(chunks)

    def pwrite(self, fd: int, data: bytes, offset: int) -> None:
        view = memoryview(data)
        while view:
            n = os.pwrite(fd, view, offset)
            view, offset = view[n:], offset + n

    def fsync(self, fd: int) -> None:
        os.fsync(fd)

    def truncate(self, fd: int, size: int) -> None:
        os.ftruncate(fd, size)

    def size(self, fd: int) -> int:
        return os.fstat(fd).st_size

    def rename(self, src: str, dst: str) -> None:
        os.rename(src, dst)

    def unlink(self, path: str) -> None:
        os.unlink(path)

    def fsync_dir(self, path: str) -> None:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

    def listdir(self, path: str) -> list[str]:
        return sorted(os.listdir(path))

    def mkdir(self, path: str) -> None:
        os.makedirs(path, mode=DIR_MODE, exist_ok=True)  # parents get the default mode

    def exists(self, path: str) -> bool:
        return os.path.exists(path)

    def lock(self, path: str) -> int | None:
        """Take an exclusive lock on `path` (created if needed); None when another holds it."""
        for _attempt in range(5):
            fd = _open_nofollow(path, os.O_RDWR | os.O_CREAT)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                return None
            # A lock on a file that was unlinked or replaced after we opened it excludes
            # nobody: the next writer opens the new file. Take the lock on what is there now.
            if self.lock_held(fd, path):
                return fd
            os.close(fd)
        raise OSError(errno.EAGAIN, "the lock file keeps being replaced; is another program "
                      "removing it?", path)  # fmt: skip

    def lock_held(self, fd: int, path: str) -> bool:
        """Whether `fd` (a lock taken by `lock`) is still the file at `path`: false once the
        file was removed or replaced, when a second writer could take a lock of its own."""
        try:
            now = os.lstat(path)
        except FileNotFoundError:
            return False
        held = os.fstat(fd)
        return (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino)

    def unlock(self, fd: int) -> None:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)

    # Convenience built on the calls above.

    def read_file(self, path: str) -> bytes:
        fd = self.open(path)
        try:
            return self.pread(fd, self.size(fd), 0)
        finally:
            self.close(fd)

    def write_file_atomic(self, path: str, data: bytes) -> None:
        """Replace `path`: write a temp file, fsync it, rename it over, fsync the directory."""
        tmp = path + ".tmp"
        if self.exists(tmp):
            self.unlink(tmp)
        fd = self.open(tmp, write=True, create=True)
        try:
            self.pwrite(fd, data, 0)
            if "rename-before-sync" not in planted.BUGS:
                self.fsync(fd)
        finally:
            self.close(fd)
        self.rename(tmp, path)
        self.fsync_dir(os.path.dirname(path) or ".")


@dataclass
class RecordingFileSystem(FileSystem):
    """The real file system, plus a log of every operation that changes what is on disk.

    Each entry is a tuple: ("create", path), ("write", path, offset, data),
    ("fsync", path), ("truncate", path, size), ("rename", src, dst), ("unlink", path),
    ("fsync_dir", path). `fail_fsync` makes fsyncs raise OSError (to test failure handling).
    """

    ops: list[tuple[Any, ...]] = field(default_factory=list)
    fail_fsync: bool = False
    _paths: dict[int, str] = field(default_factory=dict)

    def open(self, path: str, *, write: bool = False, create: bool = False) -> int:
        fd = super().open(path, write=write, create=create)
        self._paths[fd] = path
        if create:
            self.ops.append(("create", path))
        return fd

    def close(self, fd: int) -> None:
        self._paths.pop(fd, None)
        super().close(fd)

    def lock(self, path: str) -> int | None:
        fd = super().lock(path)
        if fd is not None:
            self._paths[fd] = path
        return fd

    def unlock(self, fd: int) -> None:
        self._paths.pop(fd, None)
        super().unlock(fd)

    def pwrite(self, fd: int, data: bytes, offset: int) -> None:
        self.ops.append(("write", self._paths[fd], offset, bytes(data)))
        super().pwrite(fd, data, offset)

    def fsync(self, fd: int) -> None:
        if self.fail_fsync:
            raise OSError(5, "Input/output error (injected)")
        super().fsync(fd)
        self.ops.append(("fsync", self._paths[fd]))

    def truncate(self, fd: int, size: int) -> None:
        self.ops.append(("truncate", self._paths[fd], size))
        super().truncate(fd, size)

    def rename(self, src: str, dst: str) -> None:
        self.ops.append(("rename", src, dst))
        super().rename(src, dst)

    def unlink(self, path: str) -> None:
        self.ops.append(("unlink", path))
        super().unlink(path)

    def fsync_dir(self, path: str) -> None:
        if self.fail_fsync:
            raise OSError(5, "Input/output error (injected)")
        super().fsync_dir(path)
        self.ops.append(("fsync_dir", path))

    def mark(self, label: str) -> None:
        """Put a marker in the log (tests note where a put or a sync completed)."""
        self.ops.append(("mark", label))
