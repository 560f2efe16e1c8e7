"""Crash consistency: at every operation boundary of a random workload, every disk image a
crash could leave opens to exactly a prefix of the puts, holding every synced put."""

import json
import random

import pytest

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cclogfs
from cclogfs.store.fs import RecordingFileSystem
from crashsim import MODES, DiskModel

action = st.one_of(
    st.tuples(st.just("put"), st.sampled_from(["/odom", "/tf", "../x"]), st.integers(1, 30)),
    st.tuples(st.just("sync")),
    st.tuples(st.just("reopen")),
)


def run_workload(path, actions, sync_every_bytes):
    """Run the actions; return the puts, the recorded ops, and per op how many puts were synced."""
    fs = RecordingFileSystem()
    opts = dict(fs=fs, sync_every_ms=None, sync_every_bytes=sync_every_bytes, segment_bytes=4096)
    store = cclogfs.open_store(path, create=True, **opts)
    puts, synced = [], []
    acked = 0

    def note():
        synced.extend([acked] * (len(fs.ops) - len(synced)))

    t = 0
    for act in actions:
        if act[0] == "put":
            messages = [(t + i, json.dumps({"seq": len(puts), "i": i, "pad": "p" * (i * 7 % 50)}))
                        for i in range(act[2])]  # fmt: skip
            t += act[2]
            store.put_window(act[1], messages)
            puts.append((act[1], messages))
        elif act[0] == "sync":
            store.sync()
            note()
            acked = len(puts)
        else:
            store.close()
            note()
            acked = len(puts)
            store = cclogfs.open_store(path, **opts)
        note()
    store.close()
    note()
    return puts, fs.ops, synced


def check_image(tmp_path, files, puts, must_have, reuse):
    path = tmp_path / f"img{reuse}"
    path.mkdir()
    for name, data in files.items():
        (path / name).write_bytes(data)
    if "MANIFEST" not in files:  # crash before the store was first created
        assert must_have == 0
        return
    with cclogfs.open_store(path, sync_every_ms=None) as store:
        got = sorted(store.query(), key=lambda w: w.seq)
        assert [w.seq for w in got] == list(range(len(got))), "a hole or reordering"
        assert len(got) >= must_have, f"lost synced puts: have {len(got)}, synced {must_have}"
        assert len(got) <= len(puts)
        for w, (name, messages) in zip(got, puts):
            assert (w.name, list(w.messages())) == (name, messages)
        store.put_window("/after", [(10**12, "{}")])  # the recovered store takes writes
        store.sync()
    with cclogfs.open_store(path, sync_every_ms=None) as store:
        assert store.recovery.clean
        assert sum(1 for _ in store.query()) == len(got) + 1


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(actions=st.lists(action, min_size=3, max_size=25), sync_every_bytes=st.sampled_from([None, 1500]),
       seed=st.integers(0, 2**32))  # fmt: skip
def test_every_crash_image_recovers_a_prefix(tmp_path_factory, actions, sync_every_bytes, seed):
    tmp = tmp_path_factory.mktemp("crash")
    puts, ops, synced = run_workload(tmp / "store", actions, sync_every_bytes)
    model = DiskModel()
    rng = random.Random(seed)
    n = 0
    for k, op in enumerate(ops):
        model.apply(op)
        if op[0] in ("write", "truncate", "rename", "unlink", "create", "fsync", "fsync_dir"):
            for mode in rng.sample(MODES, 2):
                check_image(tmp, model.image(rng, mode), puts, synced[k], n)
                n += 1


def test_reordered_writes_do_not_leave_a_hole(tmp_path):
    # A later group's write reached the disk, an earlier one's did not: the reader must stop
    # at the zeros, not skip them and return the later records.
    fs = RecordingFileSystem()
    with cclogfs.open_store(tmp_path / "s", create=True, fs=fs, sync_every_ms=None,
                            sync_every_bytes=None) as store:  # fmt: skip
        store.put_window("/a", [(0, "0")])
        store.sync()
        synced_at = len(fs.ops)
        for i in range(1, 4):
            store.put_window("/a", [(i, str(i))])
            store.active.flush()  # each put its own write, none synced
    model = DiskModel()
    for op in fs.ops[:synced_at]:
        model.apply(op)
    writes = [op for op in fs.ops[synced_at:] if op[0] == "write" and op[1].endswith(".seg")]
    for op in fs.ops[synced_at:]:
        if op[0] != "write" or op is writes[0]:
            continue  # the first unsynced write is lost, the later ones land
        model.apply(op)
    seg = next(n for n in model.names if n.endswith(".seg"))
    model.inodes[model.names[seg]].durable = model.inodes[model.names[seg]].current
    img = tmp_path / "img"
    img.mkdir()
    for name, data in model.image(random.Random(0), "lost").items():
        (img / name).write_bytes(data)
    with cclogfs.open_store(img) as store:
        assert [w.seq for w in store.query()] == [0]
        (problem,) = store.recovery.problems
        assert problem.reason == "zero fill"


def _killed_writer_then(tmp_path, then):
    """A writer killed with records handed to the OS but never fsynced; a second process
    opens the same store (same page cache) and runs `then(store)`; then the power fails.
    Returns the store the power loss leaves, opened."""
    fs = RecordingFileSystem()
    opts = dict(fs=fs, sync_every_ms=None, sync_every_bytes=None)
    first = cclogfs.open_store(tmp_path / "s", create=True, **opts)
    first.put_window("/a", [(0, "0")])
    first.sync()  # acknowledged
    for i in range(1, 4):
        first.put_window("/a", [(i, str(i))])
    first.active.flush()  # in the page cache only
    first._closed = True  # kill -9: nothing more of it runs
    fs.unlock(first._lock_fd)
    with cclogfs.open_store(tmp_path / "s", **opts) as second:
        assert [w.seq for w in second.query()] == [0, 1, 2, 3]
        then(second)
    model = DiskModel()
    for op in fs.ops:
        model.apply(op)
    img = tmp_path / "img"
    img.mkdir()
    for name, data in model.image(random.Random(0), "lost").items():  # only what was fsynced
        (img / name).write_bytes(data)
    return cclogfs.open_store(img, sync_every_ms=None)


def test_seal_after_a_crash_seals_only_durable_data(tmp_path):
    # Issue 11, item 5: the second process seals before any put; a power loss must not
    # leave a sealed segment whose tail lived only in the page cache.
    with _killed_writer_then(tmp_path, lambda store: store.seal()) as store:
        assert [w.seq for w in store.query()] == [0, 1, 2, 3]
        assert [list(w.messages()) for w in store.query()][0] == [(0, "0")]


def test_records_recovered_after_a_crash_are_made_durable_by_the_next_sync(tmp_path):
    # Issue 11, item 11: what the second process recovered and answered is durable.
    with _killed_writer_then(tmp_path, lambda store: store.sync()) as store:
        assert [w.seq for w in store.query()] == [0, 1, 2, 3]


def test_a_reopen_after_a_failed_fsync_rewrites_what_it_cannot_prove_durable(tmp_path):
    # Issue 11, item 8 ("fsyncgate"): after a failed fsync the kernel may mark the pages
    # clean without writing them. The reopened store must write them again, or a put
    # acknowledged after the reopen survives a power loss only in a side file.
    from cclogfs.errors import StoreFailedError

    fs = RecordingFileSystem()
    opts = dict(fs=fs, sync_every_ms=None, sync_every_bytes=None)
    store = cclogfs.open_store(tmp_path / "s", create=True, **opts)
    store.put_window("/a", [(0, "0")])
    store.sync()
    for i in (1, 2):
        store.put_window("/a", [(i, str(i))])
    seg = store.active.path
    fs.fail_fsync = True
    with pytest.raises(StoreFailedError):
        store.sync()
    fs.ops.append(("fsync_failed", seg))  # the kernel dropped the dirty pages' state
    fs.fail_fsync = False
    store.close()
    with cclogfs.open_store(tmp_path / "s", **opts) as store:  # "reopen to recover"
        store.put_window("/a", [(3, "3")])
        store.sync()  # acknowledged
    model = DiskModel()
    for op in fs.ops:
        model.apply(op)
    img = tmp_path / "img"
    img.mkdir()
    for name, data in model.image(random.Random(0), "lost").items():
        (img / name).write_bytes(data)
    with cclogfs.open_store(img, sync_every_ms=None) as store:
        assert [w.seq for w in store.query()] == [0, 1, 2, 3]
