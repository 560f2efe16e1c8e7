"""`cclog record` when the store's disk fills (RLIMIT_FSIZE stands in for a full disk: the
write fails with EFBIG as it would with ENOSPC): the error says what of the run is stored,
up to which seq, and that the rest was lost; the run's end record is written once the failed
store is closed, by reopening it (when the disk has room for it again: here recovery cut the
torn tail, which leaves room), so `cclog info` says the run ended on a store failure and
what it kept, not that it was killed or cut by a power loss."""

from __future__ import annotations

import json
import re
import resource
import subprocess
import sys

import cclogfs

CCLOG = [sys.executable, "-m", "cclogfs"]


def _limit_file_size():
    resource.setrlimit(resource.RLIMIT_FSIZE, (3 << 20, 3 << 20))  # Python ignores SIGXFSZ: writes fail


def _odom(path, n=40000):
    with open(path, "w") as f:
        for i in range(n):
            msg = {"pose": {"x": i * 0.0123456789, "y": -i * 0.0098765432}, "twist": {"vx": 0.25, "wz": -0.01 * i}}
            f.write(json.dumps({"topic": "/odom", "stamp_ns": i * 50_000_000, "msg": msg}) + "\n")


def _stored(store):
    with cclogfs.open_store(store) as s:  # the writer's reopen: recovery keeps what is whole
        return sum(w.count for w in s.query("/odom"))


def test_a_full_disk_says_what_was_synced_and_info_does_not_blame_a_kill(tmp_path):
    src, store = tmp_path / "odom.jsonl", tmp_path / "s"
    _odom(src)
    r = subprocess.run([*CCLOG, "record", str(src), "--store", str(store), "--codec", "none", "--sync-ms", "0",
                        "--chunk", "100"], capture_output=True, text=True, preexec_fn=_limit_file_size)  # fmt: skip
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    said = re.search(r"This run's messages stored: synced up to seq (\d+): ([\d,]+) messages in (\d+) windows;", r.stderr)
    assert said, r.stderr
    read = re.search(r"the rest of the ([\d,]+) messages it read was lost\. Reopened, the store keeps ([\d,]+) messages "
                     r"of this run in (\d+) windows and its end record \(`cclog info`: ended on a store failure\)",
                     r.stderr)  # fmt: skip
    assert read, r.stderr
    assert "written but not yet fsynced" not in r.stderr  # --sync-ms 0: every window fsynced as written
    synced = int(said[2].replace(",", ""))
    assert 0 < synced < int(read[1].replace(",", "")) <= 40000 and int(said[3]) == synced // 100
    assert int(read[2].replace(",", "")) == synced and int(read[3]) == synced // 100
    assert _stored(store) == synced  # exactly what the error said is what the store keeps
    info = subprocess.run([*CCLOG, "info", str(store)], capture_output=True, text=True)
    assert "no end record" not in info.stdout, info.stdout
    assert "error: ended on a store failure (disk full or failing)" in info.stdout, info.stdout
    assert f"{synced:,} of {int(read[1].replace(',', '')):,}" in info.stdout, info.stdout
    fsck = subprocess.run([*CCLOG, "fsck", str(store)], capture_output=True, text=True)
    assert fsck.returncode == 0, fsck.stdout + fsck.stderr
    # What to do next: a file is recorded whole, so --append stores what was kept twice (the
    # error said "record the rest again (--append)"; found by l-left3 on a full tmpfs).
    assert (f"free space, then record {src} again into another --store, or into this one with --append, which "
            f"stores the {synced:,} messages of this run it keeps a second time") in r.stderr, r.stderr


def test_a_full_disk_before_anything_is_stored_says_the_new_store_is_removed(tmp_path):
    """A run that stores nothing leaves no store it created, also when the disk filled: the
    error said the reopened store kept the run's end record (`cclog info`), and then the
    store was removed, so `cclog info` found none (found by attack on a full tmpfs)."""
    src, store = tmp_path / "odom.jsonl", tmp_path / "s"
    _odom(src)
    r = subprocess.run([*CCLOG, "record", str(src), "--store", str(store), "--codec", "none", "--chunk", "40000"],
                       capture_output=True, text=True, preexec_fn=_limit_file_size)  # fmt: skip
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not store.exists()
    assert "end record" not in r.stderr, r.stderr
    assert ("the rest of the 40,000 messages it read was lost; nothing of this run was stored, so the store it "
            "created was removed") in r.stderr, r.stderr
