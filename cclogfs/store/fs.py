"""The one small file-system layer every byte of store I/O goes through.

Keeping it to a few calls on file descriptors (open, pread, pwrite, fsync, truncate,
rename, unlink, fsync of a directory) lets tests record every operation and build the
disk images a crash could leave, which monkeypatching `os` cannot do for `open().write()`.
"""

from __future__ import annotations

import errno
import fcntl
import functools
import os
import stat
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from ..errors import StoreIOError

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
        fd = os.open(path, flags | (0 if "follow-symlink" in planted.BUGS else _NOFOLLOW), FILE_MODE)
    except OSError as err:
        if err.errno == errno.ELOOP:  # what O_NOFOLLOW gives for a symlink: say it plainly
            raise OSError(errno.ELOOP, "is a symbolic link, which the store never follows", path) from None
        raise
    # A directory (or fifo, device) named like a store file opens read-only: refuse it here,
    # by name, rather than fail on the first read with no file named.
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise OSError(errno.EISDIR, "is not a regular file (a directory?), which the store never uses", path)
    return fd


class FileTooLargeError(OSError):
    """A store file larger than the format allows it to be: never read into memory."""

    def __init__(self, path: str, size: int, limit: int):
        super().__init__(errno.EFBIG, f"is {size} bytes, over the {limit}-byte limit of the format", path)
        self.size, self.limit = size, limit


_F = TypeVar("_F", bound=Callable[..., Any])


def io_op(what: str) -> Callable[[_F], _F]:
    """Turn an OSError of a file operation into StoreIOError naming the file and `what`
    failed: callers that handle a failed write or fsync still catch it as an OSError, and
    no caller ever gets a raw one. A missing or existing file (ENOENT, EEXIST) stays the
    plain OSError callers test for; a held lock is no failure."""

    def wrap(fn: _F) -> _F:
        @functools.wraps(fn)
        def op(self: FileSystem, target: Any, *args: Any, **kwargs: Any) -> Any:
            try:
                return fn(self, target, *args, **kwargs)
            except (FileNotFoundError, FileExistsError, BlockingIOError, StoreIOError):
                raise
            except OSError as err:
                name = self.name_of(target) if isinstance(target, int) else target
                raise StoreIOError(err.errno or errno.EIO, err.strerror or str(err), err.filename or name,
                                   what) from err  # fmt: skip

        return op  # type: ignore[return-value]

    return wrap


class FileSystem:
    """The real file system (POSIX). Every operation's OSError (but a missing or existing
    file) reaches the caller as StoreIOError (`io_op`)."""

    def name_of(self, fd: int) -> str:
        """The path a descriptor was opened with (for error messages)."""
        return getattr(self, "_names", {}).get(fd, f"file descriptor {fd}")

    def _named(self, fd: int, path: str) -> int:
        if not hasattr(self, "_names"):
            self._names: dict[int, str] = {}
        self._names[fd] = path
        return fd

    @io_op("opening")
    def open(self, path: str, *, write: bool = False, create: bool = False) -> int:
        flags = os.O_RDWR if write else os.O_RDONLY
        if create:
            flags |= os.O_CREAT | os.O_EXCL
        return self._named(_open_nofollow(path, flags), path)

    @io_op("closing")
    def close(self, fd: int) -> None:
        getattr(self, "_names", {}).pop(fd, None)
        os.close(fd)

    @io_op("reading")
    def pread(self, fd: int, size: int, offset: int) -> bytes:
        chunks, got = [], 0
        while got < size:  # pread may return short reads for large sizes
            chunk = os.pread(fd, size - got, offset + got)
            if not chunk:
                break
            chunks.append(chunk)
            got += len(chunk)
        return chunks[0] if len(chunks) == 1 else b"".join(chunks)

    @io_op("writing")
    def pwrite(self, fd: int, data: bytes, offset: int) -> None:
        view = memoryview(data)
        while view:
            n = os.pwrite(fd, view, offset)
            view, offset = view[n:], offset + n

    @io_op("fsync")
    def fsync(self, fd: int) -> None:
        os.fsync(fd)

    @io_op("truncating")
    def truncate(self, fd: int, size: int) -> None:
        os.ftruncate(fd, size)

    @io_op("stat")
    def size(self, fd: int) -> int:
        return os.fstat(fd).st_size

    @io_op("allocating")
    def allocate(self, fd: int, size: int) -> None:
        """Make the file `size` bytes with its blocks allocated (not sparse): space set
        aside, so a later write into it cannot fail for lack of space."""
        if hasattr(os, "posix_fallocate"):
            os.posix_fallocate(fd, 0, size)
        else:  # pragma: no cover - every POSIX system cclogfs runs on has it
            os.ftruncate(fd, size)

    @io_op("statvfs")
    def free_bytes(self, path: str) -> int:
        """Bytes an unprivileged writer may still allocate on the file system of `path`."""
        st = os.statvfs(path)
        return st.f_bavail * st.f_frsize

    @io_op("stat")
    def file_size(self, path: str) -> int | None:
        """Bytes of the file at `path` (not following a symlink); None when it is gone."""
        try:
            return os.lstat(path).st_size
        except FileNotFoundError:
            return None

    def next_data(self, fd: int, offset: int) -> int:
        """The first offset at or after `offset` that may hold data: a hole of a sparse file
        reads as zeros, so searches for records skip it (the file's size when only a hole
        is left). `offset` itself where the file system cannot tell."""
        try:
            return os.lseek(fd, offset, os.SEEK_DATA)
        except OSError as err:
            if err.errno == errno.ENXIO:  # nothing but a hole from here to the end
                return max(offset, self.size(fd))
            return offset
        except AttributeError:  # pragma: no cover - no SEEK_DATA on this platform
            return offset

    @io_op("renaming")
    def rename(self, src: str, dst: str) -> None:
        os.rename(src, dst)

    @io_op("removing")
    def unlink(self, path: str) -> None:
        os.unlink(path)

    @io_op("fsync of the directory")
    def fsync_dir(self, path: str) -> None:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

    @io_op("listing")
    def listdir(self, path: str) -> list[str]:
        return sorted(os.listdir(path))

    @io_op("making the directory")
    def mkdir(self, path: str) -> None:
        os.makedirs(path, mode=DIR_MODE, exist_ok=True)  # parents get the default mode

    def exists(self, path: str) -> bool:
        return os.path.exists(path)

    @io_op("locking")
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
                return self._named(fd, path)
            os.close(fd)
        raise OSError(errno.EAGAIN, "the lock file keeps being replaced; is another program "
                      "removing it?", path)  # fmt: skip

    @io_op("checking the lock")
    def lock_held(self, fd: int, path: str) -> bool:
        """Whether `fd` (a lock taken by `lock`) is still the file at `path`: false once the
        file was removed or replaced, when a second writer could take a lock of its own."""
        try:
            now = os.lstat(path)
        except FileNotFoundError:
            return False
        held = os.fstat(fd)
        return (held.st_dev, held.st_ino) == (now.st_dev, now.st_ino)

    @io_op("unlocking")
    def unlock(self, fd: int) -> None:
        getattr(self, "_names", {}).pop(fd, None)
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)

    # Convenience built on the calls above.

    def read_file(self, path: str, limit: int | None = None) -> bytes:
        """The whole file; with `limit`, FileTooLargeError when it holds more bytes, checked
        on its size before anything is read (a sparse file costs no disk, but memory)."""
        fd = self.open(path)
        try:
            size = self.size(fd)
            if limit is not None and size > limit:
                raise FileTooLargeError(path, size, limit)
            return self.pread(fd, size, 0)
        finally:
            self.close(fd)

    def write_file_atomic(self, path: str, data: bytes) -> None:
        """Replace `path`: write a temp file, fsync it, rename it over, fsync the directory.
        A failure before the rename leaves `path` as it was (and the temp file removed, when
        it can be: on a full disk it holds the space a retry needs); one at the directory
        fsync carries `renamed = True`."""
        tmp = path + ".tmp"
        if self.exists(tmp):
            self.unlink(tmp)
        fd = self.open(tmp, write=True, create=True)
        try:
            try:
                self.pwrite(fd, data, 0)
                if "rename-before-sync" not in planted.BUGS:
                    self.fsync(fd)
            finally:
                self.close(fd)
        except OSError:
            try:
                self.unlink(tmp)
            except OSError:
                pass  # a leftover `*.tmp`, removed by the writer's next open
            raise
        self.rename(tmp, path)
        try:
            self.fsync_dir(os.path.dirname(path) or ".")
        except OSError as err:
            err.renamed = True  # the new file is in place, but whether the disk has it is unknown
            raise

    def copy_range_atomic(self, src_fd: int, start: int, end: int, path: str, *, head: bytes = b"") -> None:
        """Make `path` a copy of bytes [start, end) of the open file `src_fd`, as
        `write_file_atomic` does, in chunks (memory stays at one chunk however large the
        range) and keeping the source's holes as holes. `head`, when given, replaces the
        copy's first bytes before it is synced (repair's rebuilt segment header)."""
        tmp = path + ".tmp"
        if self.exists(tmp):
            self.unlink(tmp)
        fd = self.open(tmp, write=True, create=True)
        try:
            pos = self.next_data(src_fd, start)
            while pos < end:
                chunk = self.pread(src_fd, min(COPY_CHUNK, end - pos), pos)
                if not chunk:
                    break
                if chunk.strip(b"\0"):  # zeros stay a hole: they read back the same
                    self.pwrite(fd, chunk, pos - start)
                pos = self.next_data(src_fd, pos + len(chunk))
            self.truncate(fd, end - start)  # a hole at the end is part of the copy too
            if head:
                self.pwrite(fd, head, 0)
            self.fsync(fd)
        finally:
            self.close(fd)
        self.rename(tmp, path)
        self.fsync_dir(os.path.dirname(path) or ".")


# What `copy_range_atomic` reads at a time.
COPY_CHUNK = 4 << 20


@dataclass
class RecordingFileSystem(FileSystem):
    """The real file system, plus a log of every operation that changes what is on disk.

    Each entry is a tuple: ("create", path), ("write", path, offset, data),
    ("fsync", path), ("truncate", path, size), ("rename", src, dst), ("unlink", path),
    ("fsync_dir", path). `fail_fsync` makes fsyncs raise OSError (to test failure handling).
    """

    ops: list[tuple[Any, ...]] = field(default_factory=list)
    fail_fsync: bool = False

    def open(self, path: str, *, write: bool = False, create: bool = False) -> int:
        fd = super().open(path, write=write, create=create)
        if create:
            self.ops.append(("create", path))
        return fd

    def pwrite(self, fd: int, data: bytes, offset: int) -> None:
        self.ops.append(("write", self.name_of(fd), offset, bytes(data)))
        super().pwrite(fd, data, offset)

    @io_op("fsync")
    def fsync(self, fd: int) -> None:
        if self.fail_fsync:
            raise OSError(5, "Input/output error (injected)")
        super().fsync(fd)
        self.ops.append(("fsync", self.name_of(fd)))

    def truncate(self, fd: int, size: int) -> None:
        self.ops.append(("truncate", self.name_of(fd), size))
        super().truncate(fd, size)

    def allocate(self, fd: int, size: int) -> None:
        self.ops.append(("truncate", self.name_of(fd), size))  # the file grows by zeros
        super().allocate(fd, size)

    def rename(self, src: str, dst: str) -> None:
        self.ops.append(("rename", src, dst))
        super().rename(src, dst)

    def unlink(self, path: str) -> None:
        self.ops.append(("unlink", path))
        super().unlink(path)

    @io_op("fsync of the directory")
    def fsync_dir(self, path: str) -> None:
        if self.fail_fsync:
            raise OSError(5, "Input/output error (injected)")
        super().fsync_dir(path)
        self.ops.append(("fsync_dir", path))

    def mark(self, label: str) -> None:
        """Put a marker in the log (tests note where a put or a sync completed)."""
        self.ops.append(("mark", label))
