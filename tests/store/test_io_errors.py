"""Issue 16 item 5 (I/O part): EIO, ENOSPC, short writes and failing fsyncs at every file
operation of every store operation give a project error, lose nothing acknowledged, and
leave a store that reopens and works (the runs: tests/store/io_faults.py)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

import io_faults
from cclogfs.errors import CclogError, StoreIOError
from cclogfs.store.fs import FileSystem
from faultfs import FaultyFileSystem

# tmpfs when there is one: every run fsyncs, and what is tested is the error handling.
SHM = "/dev/shm" if Path("/dev/shm").is_dir() else None


@pytest.mark.parametrize("scenario", io_faults.SCENARIOS, ids=lambda sc: sc.name)
def test_an_io_error_at_any_operation_is_a_project_error_and_loses_nothing(scenario):
    with tempfile.TemporaryDirectory(dir=SHM) as tmp:
        out = io_faults.run_scenario(scenario, Path(tmp))
    print(f"{scenario.name}: {out.runs} injected runs, {out.errors} project errors, modes {out.modes}")
    assert out.runs >= 6  # every scenario does file operations, each failed in turn
    assert out.violations == []


def test_a_file_system_error_names_the_file_and_the_operation(tmp_path):
    fs = FileSystem()
    fd = fs.open(str(tmp_path / "f"), write=True, create=True)
    fs.close(fd)
    with pytest.raises(StoreIOError) as err:
        fs.pread(fd, 1, 0)  # a closed descriptor: EBADF
    assert isinstance(err.value, CclogError) and isinstance(err.value, OSError)
    assert "reading failed" in str(err.value)
    with pytest.raises(FileNotFoundError):  # callers test for a missing file: it stays one
        fs.open(str(tmp_path / "missing"))


def test_an_injected_fault_fails_only_the_chosen_operation(tmp_path):
    fs = FaultyFileSystem(at=2, mode="short")
    fs.arm()
    fd = fs.open(str(tmp_path / "f"), write=True, create=True)
    with pytest.raises(StoreIOError, match="No space left"):
        fs.pwrite(fd, b"abcdef", 0)
    fs.pwrite(fd, b"xyz", 10)
    fs.close(fd)
    assert (tmp_path / "f").read_bytes() == b"abc" + b"\0" * 7 + b"xyz"
    assert fs.fired == ("pwrite", "f", "short") and [k for k, _ in fs.ops] == ["create", "pwrite", "pwrite"]
