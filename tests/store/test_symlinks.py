"""Issue 16 item 2: the writer never opens, truncates or writes through a symlink; it says
which file is one, and the symlink's target stays as it was."""

import os

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import StoreError
from cclogfs.store.format import segment_name


def _store_with_records(path):
    with cclogfs.open_store(path, create=True, sync_every_ms=None) as store:
        store.put_window("/a", [(1, "{}"), (2, "{}")])
        store.sync()


def _refused(path, victim, name, capsys):
    before = victim.read_bytes()
    with pytest.raises(StoreError) as err:
        cclogfs.open_store(path, sync_every_ms=None)
    message = str(err.value)
    assert "\n" not in message and name in message and "symbolic link" in message
    assert main(["compact", str(path), "--budget", "20GiB"]) != 0
    err_line = capsys.readouterr().err.strip().splitlines()[-1]
    assert err_line.startswith("cclog: error: ") and name in err_line
    assert victim.read_bytes() == before and victim.stat().st_size == len(before)


def test_a_symlinked_lock_is_refused_and_its_target_untouched(tmp_path, capsys):
    path = tmp_path / "s"
    _store_with_records(path)
    victim = tmp_path / "victim"
    victim.write_bytes(b"precious data\n" * 10)
    os.unlink(path / "LOCK")
    os.symlink(victim, path / "LOCK")
    _refused(path, victim, "LOCK", capsys)


def test_an_active_segment_that_is_a_symlink_is_refused(tmp_path, capsys):
    path = tmp_path / "s"
    _store_with_records(path)
    seg = path / segment_name(0)
    victim = tmp_path / "victim.seg"
    victim.write_bytes(seg.read_bytes())  # an intact segment: the writer would append to it
    os.unlink(seg)
    os.symlink(victim, seg)
    _refused(path, victim, segment_name(0), capsys)


def test_an_unsealed_segment_symlink_to_a_damaged_file_is_not_truncated(tmp_path, capsys):
    path = tmp_path / "s"
    _store_with_records(path)
    seg = path / segment_name(0)
    victim = tmp_path / "victim"
    victim.write_bytes(seg.read_bytes()[:40] + b"\xff" * 200)  # recovery would cut this tail
    os.unlink(seg)
    os.symlink(victim, seg)
    _refused(path, victim, segment_name(0), capsys)
