"""A failing fsync of the checkpoint that close() writes is a project error (found by the
crash states' failed-fsync step: close() raised a raw OSError)."""

import pytest

import cclogfs
from bench._memfs import RecordingMemFileSystem
from cclogfs.errors import StoreFailedError


def test_a_failed_checkpoint_at_close_is_a_store_error_and_loses_nothing():
    fs = RecordingMemFileSystem()
    store = cclogfs.open_store("/s", create=True, fs=fs, sync_every_ms=None, sync_every_bytes=None)
    for t in (1, 2):
        store.put_window("/a", [(t, "{}")])
        store.sync()
    fs.fail_fsyncs.add(fs.fsyncs + 1)  # the checkpoint's MANIFEST.tmp
    with pytest.raises(StoreFailedError, match="checkpoint"):
        store.close()
    with cclogfs.open_store("/s", fs=fs) as store:
        assert [w.seq for w in store.query()] == [0, 1]
