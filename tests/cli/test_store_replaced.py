"""`cclog record` whose store directory is renamed away and another store put at its path while
it records (a user moving stores about, a sync tool restoring a copy). The writer notices its
LOCK is no longer its own and fails; the run's end record must then not be written by
reopening the path, which now holds another store: that wrote this run's end record into the
other store and told the user it kept the other store's messages as this run's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import cclogfs

CCLOG = [sys.executable, "-m", "cclogfs"]


def _line(i: int) -> str:
    return json.dumps({"topic": "/odom", "stamp_ns": i * 50_000_000, "msg": {"x": i * 0.5}}) + "\n"


def _files(path):
    return {name: (path / name).read_bytes() for name in sorted(os.listdir(path)) if name != "LOCK"}


def _windows(path) -> int:
    """/odom windows a reader sees in the store at `path` (0 before it exists)."""
    if not (path / "MANIFEST").exists():
        return 0
    with cclogfs.open_store(path, readonly=True) as s:
        return len(list(s.query("/odom")))


def test_a_store_replaced_under_the_recorder_gets_no_record_of_its_run(tmp_path):
    store, moved, other = tmp_path / "s", tmp_path / "s.moved", tmp_path / "other"
    with cclogfs.open_store(other, create=True) as s:
        s.put_window("/odom", [(1, '{"x": 1}')])
    proc = subprocess.Popen([*CCLOG, "record", "-", "--store", str(store), "--chunk", "10", "--sync-ms", "0"],
                            stdin=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    for i in range(50):
        proc.stdin.write(_line(i))
    proc.stdin.flush()
    deadline = time.monotonic() + 60
    while not _windows(store):
        assert time.monotonic() < deadline and proc.poll() is None, "the recorder stored nothing"
        time.sleep(0.05)
    os.rename(store, moved)
    os.rename(other, store)  # another store at the recorder's path
    before = _files(store)
    for i in range(50, 200):
        proc.stdin.write(_line(i))
    proc.stdin.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=60) != 0, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert _files(store) == before, "the recorder wrote into the store that took its path"
    assert "Reopened, the store keeps" not in err, err
    assert "replaced" in err, err
    assert _windows(moved) >= 1  # the recorder's own store keeps what it synced
