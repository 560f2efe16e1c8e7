"""Issue 16 item 6: the reserve that lets retention relieve a full disk, and errors that say
truly what state a failed drop or rewrite left the store in (FORMAT.md, "Reserve")."""

from __future__ import annotations

import json

import pytest

import cclogfs
from cclogfs.errors import StoreError, StoreFailedError
from cclogfs.store import Replacement
from cclogfs.store.format import RESERVE, reserve_bytes
from faultfs import FaultyFileSystem

OPTS = {"segment_records": 2, "sync_every_ms": None, "codec": "zstd"}


def _store(path, fs=None, n=6):
    store = cclogfs.open_store(path, create=True, fs=fs, **OPTS)
    for i in range(n):
        store.put_window("/a", [(i * 10 + k, json.dumps({"v": k * 0.5})) for k in range(5)])
    store.sync()
    return store


def test_a_writer_keeps_a_reserve_sized_by_its_manifest(tmp_path):
    with _store(tmp_path / "s") as store:
        size = (tmp_path / "s" / RESERVE).stat().st_size
        assert size == reserve_bytes((tmp_path / "s" / "MANIFEST").stat().st_size) >= 1 << 20
        assert store.data_bytes() < size  # not counted in the budget
    with cclogfs.open_store(tmp_path / "s", readonly=True):
        pass
    assert (tmp_path / "s" / RESERVE).stat().st_size == size


class FailsOnce(FaultyFileSystem):
    """Fails the first operation `kind` on a file named `name` once armed."""

    def __init__(self, kind: str, name: str, mode: str):
        super().__init__(mode=mode)
        self.want = (kind, name)

    def _step(self, kind, path):
        import os

        if self.armed and self.fired is None and (kind, os.path.basename(path)) == self.want:
            self.at = self.count + 1
        return super()._step(kind, path)


def test_a_drop_that_cannot_write_its_manifest_changes_nothing_and_the_store_goes_on(tmp_path):
    fs = FailsOnce("pwrite", "MANIFEST.tmp", "enospc")
    with _store(tmp_path / "s", fs) as store:
        before = [s.first_seq for s in store.sealed_segments()]
        fs.arm()
        with pytest.raises(StoreError, match="failed before its commit.*nothing changed") as err:
            store.drop_oldest()
        assert not isinstance(err.value, StoreFailedError)
        assert [s.first_seq for s in store.sealed_segments()] == before
        assert (tmp_path / "s" / RESERVE).exists()  # set aside again
        assert not (tmp_path / "s" / "MANIFEST.tmp").exists()  # its space freed for a retry
        assert store.drop_oldest().first_seq == before[0]  # the retry works
        store.put_window("/a", [(100, "1")])
        store.sync()


def test_a_drop_whose_directory_fsync_fails_says_the_outcome_is_unknown(tmp_path):
    fs = FailsOnce("fsync_dir", "s", "fsync")
    store = _store(tmp_path / "s", fs)
    first = store.sealed_segments()[0].first_seq
    fs.arm()
    with pytest.raises(StoreFailedError, match="renamed into place.*unknown"):
        store.drop_oldest()
    with pytest.raises(StoreFailedError):
        store.put_window("/a", [(100, "1")])
    store.close()
    with cclogfs.open_store(tmp_path / "s", **OPTS) as again:  # follows the manifest the disk holds
        assert again.first_seq > first


def test_a_rewrite_that_cannot_write_its_manifest_leaves_no_new_generation(tmp_path):
    fs = FailsOnce("create", "MANIFEST.tmp", "enospc")
    with _store(tmp_path / "s", fs) as store:
        fs.arm()
        with pytest.raises(StoreError, match="failed before its commit.*nothing changed"):
            store.rewrite(lambda w: Replacement(list(w.messages()), dict(w.meta), codec="none"))
        assert not [p.name for p in (tmp_path / "s").iterdir() if "-1." in p.name]
        assert all(s.gen == 0 for s in store.sealed_segments())
        store.put_window("/a", [(100, "1")])
        store.sync()


def test_a_reserve_that_does_not_fit_is_no_error_and_is_set_aside_later(tmp_path):
    # On a full disk the reserve stays short: opening works, and it is set aside again later.
    fs = FailsOnce("allocate", RESERVE, "enospc")
    fs.arm()
    with _store(tmp_path / "s", fs) as store:
        assert fs.fired == ("allocate", RESERVE, "enospc")
        assert store.ensure_reserve()  # the disk has room again
        assert (tmp_path / "s" / RESERVE).stat().st_size >= 1 << 20
