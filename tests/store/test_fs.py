"""cclogfs.store.fs: the file-system layer all store I/O goes through, and the recording
variant crash tests build disk images from."""

import os

import pytest

import cclogfs
from cclogfs.store.fs import FileSystem, RecordingFileSystem


def test_open_create_is_exclusive(tmp_path):
    fs, path = FileSystem(), str(tmp_path / "f")
    fs.close(fs.open(path, write=True, create=True))
    with pytest.raises(FileExistsError):
        fs.open(path, write=True, create=True)
    with pytest.raises(FileNotFoundError):
        fs.open(str(tmp_path / "missing"))


def test_pwrite_pread_size_truncate(tmp_path):
    fs = FileSystem()
    fd = fs.open(str(tmp_path / "f"), write=True, create=True)
    try:
        data = os.urandom(3 << 20)  # several MB: reads and writes may be short
        fs.pwrite(fd, data, 0)
        fs.pwrite(fd, b"XY", 5)
        assert fs.size(fd) == len(data)
        assert fs.pread(fd, 4, 3) == data[3:5] + b"XY"
        assert fs.pread(fd, len(data), 0) == data[:5] + b"XY" + data[7:]
        assert fs.pread(fd, 100, len(data) - 10) == data[-10:]  # past the end: what there is
        assert fs.pread(fd, 10, len(data) + 5) == b""
        fs.truncate(fd, 100)
        fs.fsync(fd)
        assert fs.size(fd) == 100
    finally:
        fs.close(fd)


def test_pread_on_a_read_only_fd_cannot_write(tmp_path):
    fs, path = FileSystem(), tmp_path / "f"
    path.write_bytes(b"abc")
    fd = fs.open(str(path))
    try:
        with pytest.raises(OSError):
            fs.pwrite(fd, b"z", 0)
    finally:
        fs.close(fd)
    assert path.read_bytes() == b"abc"


def test_write_file_atomic_replaces_and_clears_a_stale_tmp(tmp_path):
    fs, path = FileSystem(), tmp_path / "M"
    path.write_bytes(b"old")
    (tmp_path / "M.tmp").write_bytes(b"left by a crash")
    fs.write_file_atomic(str(path), b"new contents")
    assert fs.read_file(str(path)) == b"new contents"
    assert sorted(os.listdir(tmp_path)) == ["M"]


def test_listdir_sorted_mkdir_exists_rename_unlink(tmp_path):
    fs = FileSystem()
    fs.mkdir(str(tmp_path / "d"))
    fs.mkdir(str(tmp_path / "d"))  # already there: fine
    for name in ("b", "a", "c"):
        (tmp_path / "d" / name).write_bytes(b"")
    assert fs.listdir(str(tmp_path / "d")) == ["a", "b", "c"]
    fs.rename(str(tmp_path / "d" / "a"), str(tmp_path / "d" / "z"))
    fs.unlink(str(tmp_path / "d" / "b"))
    fs.fsync_dir(str(tmp_path / "d"))
    assert fs.listdir(str(tmp_path / "d")) == ["c", "z"]
    assert fs.exists(str(tmp_path / "d" / "z")) and not fs.exists(str(tmp_path / "d" / "a"))


def test_lock_is_exclusive_until_unlocked(tmp_path):
    fs, path = FileSystem(), str(tmp_path / "LOCK")
    first = fs.lock(path)
    assert first is not None
    assert fs.lock(path) is None  # a second holder (flock is per open file) is refused
    fs.unlock(first)
    again = fs.lock(path)
    assert again is not None
    fs.unlock(again)


def test_recording_fs_logs_every_change_in_order(tmp_path):
    fs = RecordingFileSystem()
    path = str(tmp_path / "f")
    fd = fs.open(path, write=True, create=True)
    fs.pwrite(fd, b"abc", 0)
    fs.fsync(fd)
    fs.truncate(fd, 1)
    fs.pread(fd, 1, 0)  # reads change nothing: not logged
    fs.close(fd)
    fs.mark("done")
    fs.rename(path, path + "2")
    fs.fsync_dir(str(tmp_path))
    fs.unlink(path + "2")
    assert fs.ops == [
        ("create", path), ("write", path, 0, b"abc"), ("fsync", path), ("truncate", path, 1),
        ("mark", "done"), ("rename", path, path + "2"), ("fsync_dir", str(tmp_path)), ("unlink", path + "2"),
    ]  # fmt: skip


def test_recording_fs_injected_fsync_failure_is_not_logged_as_done(tmp_path):
    fs = RecordingFileSystem(fail_fsync=True)
    fd = fs.open(str(tmp_path / "f"), write=True, create=True)
    try:
        with pytest.raises(OSError, match="injected"):
            fs.fsync(fd)
        with pytest.raises(OSError, match="injected"):
            fs.fsync_dir(str(tmp_path))
    finally:
        fs.close(fd)
    assert [op[0] for op in fs.ops] == ["create"]


def test_a_store_does_all_its_writes_through_its_fs(tmp_path):
    fs = RecordingFileSystem()
    with cclogfs.open_store(tmp_path / "s", create=True, fs=fs, sync_every_ms=None) as store:
        store.put_window("/a", [(1, "{}")])
        store.sync()
    made = {os.path.basename(op[1]) for op in fs.ops if op[0] == "create"}
    made |= {os.path.basename(op[2]) for op in fs.ops if op[0] == "rename"}
    on_disk = set(os.listdir(tmp_path / "s")) - {"LOCK"}  # the lock holds no data
    assert on_disk and on_disk <= made


def test_store_files_are_owner_only(tmp_path, monkeypatch):
    """Issue 16 item 8: a robot's logs are not world-readable (0600 files, 0700 dirs)."""
    os.umask(0o022)  # the common default; the store must not rely on a strict umask
    made_dirs = []
    real_mkdir = FileSystem.mkdir
    monkeypatch.setattr(FileSystem, "mkdir", lambda self, p: (made_dirs.append(p), real_mkdir(self, p))[1])
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, sync_every_ms=None) as store:
        store.put_window("/a", [(1, "{}")])
        store.sync()
        assert store.seal()
        store.put_window("/a", [(2, "{}")])
        store.seal()
        store.rewrite(lambda w: None)
        store.drop_oldest()
    assert any(".creating-" in p for p in made_dirs)  # the hidden sibling it is made in
    assert os.stat(path).st_mode & 0o777 == 0o700
    names = os.listdir(path)
    assert {"LOCK", "MANIFEST"} <= set(names) and any(n.endswith(".seg") for n in names)
    assert any(n.endswith(".idx") for n in names)
    for name in names:
        assert os.stat(path / name).st_mode & 0o777 == 0o600, name


def test_two_creating_one_store_at_once_one_wins(tmp_path, monkeypatch):
    """Two writers creating the same new store: the one whose rename comes second found the
    store there (ENOTEMPTY), failed with a raw 'Directory not empty' and left the CLI to
    remove the store the first was writing. Now it opens what the first made, as a second
    writer: locked. (Found by an attack: 3 of 6 concurrent `cclog record` left no store.)"""
    from cclogfs.errors import StoreLockedError

    path = str(tmp_path / "s")
    real_rename, first = FileSystem.rename, []

    def rename(self, src, dst):
        if dst == path and not first:  # the other process gets there just before this one
            first.append(None)
            with monkeypatch.context() as other:  # another pid: its own hidden sibling
                other.setattr(os, "getpid", os.getppid)
                first[0] = cclogfs.open_store(path, create=True, sync_every_ms=None)
        return real_rename(self, src, dst)

    monkeypatch.setattr(FileSystem, "rename", rename)
    with pytest.raises(StoreLockedError, match="locked by another writer"):
        cclogfs.open_store(path, create=True)
    first[0].put_window("/a", [(1, "{}")])
    first[0].close()
    assert not [n for n in os.listdir(tmp_path) if ".creating-" in n]
    with cclogfs.open_store(path, readonly=True) as store:
        assert [[tuple(m) for m in w.messages()] for w in store.query()] == [[(1, "{}")]]


@pytest.mark.parametrize("target", ["missing/store", "empty"])
def test_a_store_path_that_is_a_symbolic_link_is_followed(tmp_path, target):
    """l-atk6: a --store path that is a dangling symbolic link failed with "Not a directory
    (.../.s.creating-PID)", naming a temporary path (rename() does not follow a link), and
    so did a link to an empty directory. The store is made where the link points."""
    (tmp_path / "empty").mkdir()
    link = tmp_path / "s"
    link.symlink_to(tmp_path / target)
    with cclogfs.open_store(link, create=True, sync_every_ms=None) as store:
        store.put_window("/a", [(1, "{}")])
    assert link.is_symlink() and (tmp_path / target / "MANIFEST").is_file()
    assert not [n for n in os.listdir(tmp_path) + os.listdir(link.resolve().parent) if ".creating-" in n]
    with cclogfs.open_store(link, readonly=True) as store:
        assert store.streams()["/a"]["messages"] == 1
