"""Issue 16 items 5 and 6 on a real full disk: a small tmpfs this test mounts itself.

`cclog record` runs until the disk is full (a one-line error, nothing synced lost), some
other program takes the last free bytes, then `cclog compact --budget` (with aging too)
relieves the disk, and recording goes on. Needs root (or `unshare -rm`) to mount: skipped
without, except in CI (CI=true), where it fails.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.store import check_store

DISK_BYTES = 4 << 20


def _can_mount() -> bool:
    return os.geteuid() == 0 and shutil.which("mount") is not None


def _unshare_works() -> bool:
    return shutil.which("unshare") is not None and subprocess.run(
        ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"], capture_output=True
    ).returncode == 0  # fmt: skip


def _odom_lines(path: Path, start: int, n: int) -> None:
    """JSON Lines of 20 Hz odometry, ~250 bytes of JSON a message."""
    with open(path, "w") as f:
        for i in range(start, start + n):
            msg = {"header": {"stamp": {"sec": i // 20, "nanosec": i % 20 * 50_000_000}, "frame_id": "odom"},
                   "pose": {"x": i * 0.0123456789, "y": -i * 0.0098765432, "z": 0.0, "yaw": (i % 628) / 100.0},
                   "twist": {"vx": 0.25 + (i % 7) * 0.001234567, "wz": -0.01 * (i % 13)}}  # fmt: skip
            f.write(json.dumps({"topic": "/odom", "stamp_ns": i * 50_000_000, "msg": msg}) + "\n")


def _stamps(store_path: Path) -> list[int]:
    with cclogfs.open_store(store_path, readonly=True) as store:
        return [t for w in store.query("/odom") for t, _ in w.messages()]


def _fill(disk: Path) -> None:
    """Another program takes every byte left (the disk is full whatever the store does)."""
    try:
        with open(disk / "other-program.dat", "wb") as f:
            while True:
                f.write(b"\1" * 4096)
                f.flush()
    except OSError:
        pass  # full (perhaps already: then not even a new file fits)
    assert shutil.disk_usage(disk).free < 64 << 10


def _full_disk_scenario(disk: Path, work: Path, capsys, aging: bool) -> None:
    store = disk / "robot.store"
    _odom_lines(work / "a.jsonl", 0, 24_000)  # ~6 MiB of JSON, stored uncompressed: more than the disk
    # Segments of 1 MiB (an eighth of the budget): the disk fills before the budget is reached.
    rc = main(["record", str(work / "a.jsonl"), "--store", str(store), "--codec", "none", "--budget", "8MiB"])
    err = capsys.readouterr().err
    assert rc == 1 and "No space left on device" in err and "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("cclog: error: ")
    kept = _stamps(store)
    assert kept and kept == [i * 50_000_000 for i in range(len(kept))]  # a prefix: no hole
    assert not check_store(str(store)).errors
    with cclogfs.open_store(store):  # the writer cuts the torn tail the full disk left
        pass
    _fill(disk)  # then the disk is full whatever the store frees on open
    compact = ["compact", str(store), "--budget", "2MiB"]
    if aging:  # aging needs room for a rewrite: retention must come first
        compact += ["--older-than", "0s", "--error", "1e-3"]
    rc = main(compact)
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert "dropped" in out and "budget 2.0 MiB: met" in out
    left = _stamps(store)
    assert left and left == kept[len(kept) - len(left):]  # the oldest went, the rest is intact
    assert not check_store(str(store)).errors
    # Recording goes on, with the budget the disk affords.
    _odom_lines(work / "b.jsonl", 24_000, 6_000)
    rc = main(["record", str(work / "b.jsonl"), "--store", str(store), "--codec", "none", "--budget", "2MiB"])
    err = capsys.readouterr().err
    assert rc == 0, err
    after = _stamps(store)  # what the budget keeps: the newest of each run, with no hole
    old = [t for t in after if t < 24_000 * 50_000_000]
    new = after[len(old):]
    assert old == kept[len(kept) - len(old):]
    assert len(new) > 4000 and new == [i * 50_000_000 for i in range(30_000 - len(new), 30_000)]
    with cclogfs.open_store(store, readonly=True) as s:
        assert s.data_bytes() <= 2 << 20
    assert not check_store(str(store)).errors


@pytest.mark.parametrize("aging", [False, True], ids=["budget", "budget+aging"])
def test_a_full_disk_is_relieved_by_compact_budget_and_recording_goes_on(tmp_path, capsys, aging):
    disk = tmp_path / "disk"
    disk.mkdir()
    if _can_mount():
        subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={DISK_BYTES}", "tmpfs", str(disk)], check=True)
        try:
            _full_disk_scenario(disk, tmp_path, capsys, aging)
        finally:
            subprocess.run(["umount", str(disk)], check=True)
        return
    if _unshare_works():  # an unprivileged user: a mount namespace of our own
        script = (f"import sys; sys.path[:0] = {sys.path!r}; from pathlib import Path; "
                  f"import test_full_disk as t; t._run_alone(Path({str(disk)!r}), Path({str(tmp_path)!r}), {aging!r})")
        cmd = f"mount -t tmpfs -o size={DISK_BYTES} tmpfs {disk} && {sys.executable} -c {json.dumps(script)}"
        done = subprocess.run(["unshare", "-rm", "sh", "-c", cmd], capture_output=True, text=True)
        assert done.returncode == 0, done.stdout + done.stderr
        return
    if os.environ.get("CI") == "true":
        pytest.fail("cannot mount a tmpfs (not root, no unshare -rm), and CI must not skip the full-disk test")
    pytest.skip("cannot mount a tmpfs here (not root, no unshare -rm)")


class _Capture:
    """capsys for a run outside pytest (in an unshared mount namespace)."""

    def __init__(self) -> None:
        import io

        self.out, self.err = io.StringIO(), io.StringIO()
        sys.stdout, sys.stderr = self.out, self.err

    def readouterr(self) -> tuple[str, str]:
        out, err = self.out.getvalue(), self.err.getvalue()
        self.out.seek(0), self.out.truncate(), self.err.seek(0), self.err.truncate()
        return type("R", (tuple,), {"out": property(lambda r: r[0]), "err": property(lambda r: r[1])})((out, err))


def _run_alone(disk: Path, work: Path, aging: bool) -> None:
    _full_disk_scenario(disk, work, _Capture(), aging)


@contextlib.contextmanager
def _tmpfs(path: Path, size: int):
    """A tmpfs of `size` bytes mounted at `path` (root only; skipped otherwise, failed in CI)."""
    if not _can_mount():
        if os.environ.get("CI") == "true":
            pytest.fail("cannot mount a tmpfs (not root), and CI must not skip the full-disk tests")
        pytest.skip("cannot mount a tmpfs here (not root)")
    path.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], check=True)
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=True)


def test_record_and_compact_on_a_read_only_file_system_say_so_in_one_line(tmp_path, capsys):
    _odom_lines(tmp_path / "a.jsonl", 0, 50)
    with _tmpfs(tmp_path / "disk", 1 << 20) as disk:
        assert main(["record", str(tmp_path / "a.jsonl"), "--store", str(disk / "s")]) == 0
        subprocess.run(["mount", "-o", "remount,ro", str(disk)], check=True)
        capsys.readouterr()
        for argv in (["record", str(tmp_path / "a.jsonl"), "--store", str(disk / "s")],
                     ["record", str(tmp_path / "a.jsonl"), "--store", str(disk / "new")],
                     ["compact", str(disk / "s"), "--budget", "1KiB"]):  # fmt: skip
            assert main(argv) == 1
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and "cclog: error: " in err and "Read-only file system" in err
        assert sorted(p.name for p in disk.iterdir()) == ["s"]


def test_creating_a_store_on_a_full_disk_leaves_nothing(tmp_path, capsys):
    _odom_lines(tmp_path / "a.jsonl", 0, 50)
    with _tmpfs(tmp_path / "disk", 64 << 10) as disk:
        _fill(disk)
        assert main(["record", str(tmp_path / "a.jsonl"), "--store", str(disk / "new")]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "No space left on device" in err
        assert sorted(p.name for p in disk.iterdir()) == ["other-program.dat"]
