"""An in-memory FileSystem (cclogfs/store/fs.py's interface): crash images open in
microseconds instead of milliseconds, so a test can check a hundred thousand of them.

Same calls, same errors as the real one for what the store does (ENOENT, EEXIST, an
exclusive lock per file). The store uses the real `os` in a few places (the parent
directory on create, `data_bytes`, fsck's listing): those see nothing here, so budgets and
fsck run on the real file system (RecordingFileSystem) instead.
"""

from __future__ import annotations

import errno
import os
import threading
from typing import Any

from cclogfs.store.fs import FileSystem


class _File:
    __slots__ = ("data",)

    def __init__(self, data: bytes = b""):
        self.data = bytearray(data)


class MemFileSystem(FileSystem):
    """Files are byte arrays named by their full path; directories a set of paths."""

    def __init__(self, files: dict[str, bytes] | None = None, dirs: set[str] | None = None):
        self.files: dict[str, _File] = {p: _File(d) for p, d in (files or {}).items()}
        self.dirs: set[str] = set(dirs or ())
        self.fds: dict[int, tuple[str, _File]] = {}
        self.locks: dict[int, int] = {}  # id(file) -> fd holding its lock
        self._next = 1000
        self._mutex = threading.Lock()

    @classmethod
    def holding(cls, directory: str, files: dict[str, bytes]) -> MemFileSystem:
        """A file system whose `directory` holds `files` (name -> bytes)."""
        return cls({os.path.join(directory, n): d for n, d in files.items()}, {directory})

    def _new_fd(self, path: str, f: _File) -> int:
        with self._mutex:
            self._next += 1
            self.fds[self._next] = (path, f)
            return self._next

    def open(self, path: str, *, write: bool = False, create: bool = False) -> int:
        f = self.files.get(path)
        if create:
            if f is not None or path in self.dirs:
                raise FileExistsError(errno.EEXIST, "File exists", path)
            if os.path.dirname(path) not in self.dirs:
                raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)
            f = self.files[path] = _File()
        elif f is None:
            if path in self.dirs:
                raise IsADirectoryError(errno.EISDIR, "Is a directory", path)
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)
        return self._new_fd(path, f)

    def close(self, fd: int) -> None:
        self.fds.pop(fd)

    def pread(self, fd: int, size: int, offset: int) -> bytes:
        return bytes(self.fds[fd][1].data[offset : offset + size])

    def pwrite(self, fd: int, data: bytes, offset: int) -> None:
        buf = self.fds[fd][1].data
        if len(buf) < offset:
            buf.extend(b"\0" * (offset - len(buf)))
        buf[offset : offset + len(data)] = data

    def fsync(self, fd: int) -> None:
        self.fds[fd]  # noqa: B018 (a closed fd is an error, as for the real call)

    def truncate(self, fd: int, size: int) -> None:
        buf = self.fds[fd][1].data
        del buf[size:]
        buf.extend(b"\0" * (size - len(buf)))

    def size(self, fd: int) -> int:
        return len(self.fds[fd][1].data)

    # The store's space and sparse-file calls work on real descriptors and paths: here they
    # must never reach the os module (a fake descriptor may be some real file's number).

    def allocate(self, fd: int, size: int) -> None:
        """Nothing: memory never runs short, and a RESERVE of a MiB of zeros copied into every
        crash image made the crash states 15 times slower for bytes nobody reads."""

    def free_bytes(self, path: str) -> int:
        return 1 << 40  # no full disk in this model (tests/cli/test_full_disk.py has a real one)

    def file_size(self, path: str) -> int | None:
        f = self.files.get(path)
        return None if f is None else len(f.data)

    def next_data(self, fd: int, offset: int) -> int:
        return offset  # no holes in memory

    def rename(self, src: str, dst: str) -> None:
        if src in self.dirs:  # a store made in a hidden directory, then moved into place
            if dst in self.dirs and self.listdir(dst):
                raise OSError(errno.ENOTEMPTY, "Directory not empty", dst)
            self.dirs.discard(src)
            self.dirs.add(dst)
            for path in [p for p in self.files if os.path.dirname(p) == src]:
                self.files[os.path.join(dst, os.path.basename(path))] = self.files.pop(path)
            return
        if src not in self.files:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", src)
        self.files[dst] = self.files.pop(src)

    def unlink(self, path: str) -> None:
        if self.files.pop(path, None) is None:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)

    def fsync_dir(self, path: str) -> None:
        if path not in self.dirs:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)

    def listdir(self, path: str) -> list[str]:
        if path not in self.dirs:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)
        names = [os.path.basename(p) for p in self.files if os.path.dirname(p) == path]
        names += [os.path.basename(d) for d in self.dirs if os.path.dirname(d) == path and d != path]
        return sorted(names)

    def mkdir(self, path: str) -> None:
        while path and path not in self.dirs:
            self.dirs.add(path)
            path = os.path.dirname(path)

    def exists(self, path: str) -> bool:
        return path in self.files or path in self.dirs

    def lock(self, path: str) -> int | None:
        if path not in self.files:
            self.open(path, write=True, create=True)
        f = self.files[path]
        with self._mutex:
            if id(f) in self.locks and self.locks[id(f)] in self.fds:
                return None
        fd = self._new_fd(path, f)
        self.locks[id(f)] = fd
        return fd

    def lock_held(self, fd: int, path: str) -> bool:
        return self.files.get(path) is self.fds[fd][1]

    def unlock(self, fd: int) -> None:
        self.locks.pop(id(self.fds[fd][1]), None)
        self.close(fd)

    def contents(self, directory: str) -> dict[str, bytes]:
        """name -> bytes of the files in `directory`."""
        return {os.path.basename(p): bytes(f.data) for p, f in self.files.items() if os.path.dirname(p) == directory}


class RecordingMemFileSystem(MemFileSystem):
    """MemFileSystem plus the operation log of RecordingFileSystem (same tuples), and
    injected fsync failures: `fail_fsyncs` holds the numbers (1 = the first) of the fsyncs
    to fail; each failure is logged as ("fsync_failed", path)."""

    def __init__(self, files: dict[str, bytes] | None = None, dirs: set[str] | None = None):
        super().__init__(files, dirs)
        self.ops: list[tuple[Any, ...]] = []
        self.fail_fsyncs: set[int] = set()
        self.fsyncs = 0

    def open(self, path: str, *, write: bool = False, create: bool = False) -> int:
        fd = super().open(path, write=write, create=create)
        if create:
            self.ops.append(("create", path))
        return fd

    def lock(self, path: str) -> int | None:
        if path not in self.files:
            self.ops.append(("create", path))
        return super().lock(path)

    def pwrite(self, fd: int, data: bytes, offset: int) -> None:
        self.ops.append(("write", self.fds[fd][0], offset, bytes(data)))
        super().pwrite(fd, data, offset)

    def _failing(self) -> bool:
        self.fsyncs += 1
        return self.fsyncs in self.fail_fsyncs

    def fsync(self, fd: int) -> None:
        path = self.fds[fd][0]
        if self._failing():
            self.ops.append(("fsync_failed", path))
            raise OSError(errno.EIO, "Input/output error (injected)", path)
        self.ops.append(("fsync", path))

    def truncate(self, fd: int, size: int) -> None:
        self.ops.append(("truncate", self.fds[fd][0], size))
        super().truncate(fd, size)

    def rename(self, src: str, dst: str) -> None:
        super().rename(src, dst)
        self.ops.append(("rename", src, dst))

    def unlink(self, path: str) -> None:
        super().unlink(path)
        self.ops.append(("unlink", path))

    def fsync_dir(self, path: str) -> None:
        super().fsync_dir(path)
        if self._failing():
            raise OSError(errno.EIO, "Input/output error (injected)", path)
        self.ops.append(("fsync_dir", path))
