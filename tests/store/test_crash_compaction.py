"""Crash consistency of compaction and retention: at every operation boundary of seal,
rewrite and drop_oldest, every disk image a crash could leave opens to exactly the state
before the step or exactly the state after it, with no leftover file surviving the
writer's open."""

import json
import os
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cclogfs
from cclogfs.errors import CclogError
from cclogfs.store.fs import RecordingFileSystem
from cclogfs.store import check_store
from crashsim import MODES, DiskModel
from _rewrite import leftovers, random_rewrite, state

OPTS = dict(sync_every_ms=None, sync_every_bytes=None, segment_records=2)
step = st.one_of(
    st.tuples(st.just("rewrite"), st.integers(0, 2**32)),
    st.tuples(st.just("drop")),
    st.tuples(st.just("seal")),
    st.tuples(st.just("reopen")),
)


def run_workload(path, n_puts, steps, fs):
    """Puts (all synced), then the compaction steps. Returns the ops index where the steps
    begin, the state after each completed step (states[0]: before any), and per op how many
    steps had completed."""
    store = cclogfs.open_store(path, create=True, fs=fs, **OPTS)
    for i in range(n_puts):
        name = ("/odom", "/tf")[i % 3 == 0]
        store.put_window(name, [(i * 100 + k, json.dumps({"i": i, "k": k, "x": k * 0.1})) for k in range(1 + i % 5)],
                         meta={"i": i})  # fmt: skip
    store.sync()
    begin = len(fs.ops)
    states, done = [state(store)], []

    def note():
        done.extend([len(states) - 1] * (len(fs.ops) - len(done)))

    note()
    for act in steps:
        if act[0] == "rewrite":
            store.rewrite(random_rewrite(act[1]))
        elif act[0] == "drop":
            store.drop_oldest()
        elif act[0] == "seal":
            store.seal()
        else:
            store.close()
            store = cclogfs.open_store(path, fs=fs, **OPTS)
        note()
        states.append(state(store))
        note()
    store.close()
    note()
    return begin, states, done


def check_image(tmp_path, files, states, done, n):
    """Open the image as the writer: its state is the last completed step's or the next's."""
    path = tmp_path / f"img{n}"
    path.mkdir()
    for name, data in files.items():
        (path / name).write_bytes(data)
    with cclogfs.open_store(path, **OPTS) as store:
        got = state(store)
        assert got in states[done : done + 2], f"a mix of states or a lost step (completed steps: {done})"
        assert leftovers(path, store.manifest) == [], "a leftover survived the writer's open"
        store.put_window("/after", [(10**12, "{}")])  # the recovered store takes writes
        store.sync()
    report = check_store(str(path), deep=True)
    assert not report.findings, [str(f) for f in report.findings]


def crash_everywhere(tmp_path, ops, begin, states, done, seed, modes=2):
    model = DiskModel()
    rng = random.Random(seed)
    n = 0
    for k, op in enumerate(ops):
        model.apply(op)
        if k >= begin - 1 and op[0] != "mark":
            for mode in rng.sample(MODES, modes):
                check_image(tmp_path, model.image(rng, mode), states, done[k], n)
                n += 1
    return n


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n_puts=st.integers(3, 9), steps=st.lists(step, min_size=1, max_size=5), seed=st.integers(0, 2**32))
def test_every_crash_image_is_the_old_or_the_new_state(tmp_path_factory, n_puts, steps, seed):
    tmp = tmp_path_factory.mktemp("crash")
    fs = RecordingFileSystem()
    begin, states, done = run_workload(tmp / "store", n_puts, steps, fs)
    crash_everywhere(tmp, fs.ops, begin, states, done, seed)


def test_a_fixed_rewrite_and_drop_checks_every_image_in_every_mode(tmp_path):
    # One workload where each step surely changes the store, crashed in every mode.
    fs = RecordingFileSystem()
    steps = [("seal",), ("rewrite", 1), ("drop",), ("rewrite", 7), ("drop",), ("drop",)]
    begin, states, done = run_workload(tmp_path / "store", 7, steps, fs)
    assert len({repr(s) for s in states}) >= 5  # the steps did change what the store holds
    assert crash_everywhere(tmp_path, fs.ops, begin, states, done, 0, modes=len(MODES)) > 100


class ManifestBeforeDataFileSystem(RecordingFileSystem):
    """A broken writer: the new generation's data is not fsynced before the manifest names it."""

    def fsync(self, fd):
        if "-" in self.name_of(fd).rsplit("/", 1)[-1] and self.name_of(fd).endswith(".seg"):
            return
        super().fsync(fd)


def test_checking_the_checks_a_manifest_before_the_data_is_caught(tmp_path):
    fs = ManifestBeforeDataFileSystem()
    begin, states, done = run_workload(tmp_path / "store", 6, [("seal",), ("rewrite", 3)], fs)
    assert states[-1] != states[-2]
    with pytest.raises((AssertionError, CclogError)):
        crash_everywhere(tmp_path, fs.ops, begin, states, done, 0, modes=len(MODES))


class UnlinkBeforeCommitFileSystem(RecordingFileSystem):
    """A broken writer: once marked, it deletes the first segment before replacing the manifest."""

    def rename(self, src, dst):
        if dst.endswith("MANIFEST") and ("mark", "drop") in self.ops:
            first = os.path.join(os.path.dirname(dst), "00000000000000000000.seg")
            if os.path.exists(first):
                self.unlink(first)
                self.fsync_dir(os.path.dirname(dst))
        super().rename(src, dst)


def test_checking_the_checks_deleting_before_the_commit_is_caught(tmp_path):
    fs = UnlinkBeforeCommitFileSystem()
    path = tmp_path / "store"
    with cclogfs.open_store(path, create=True, fs=fs, **OPTS) as store:
        for i in range(4):
            store.put_window("/a", [(i, "1")])
        store.sync()
        begin = len(fs.ops)
        before = state(store)
        fs.mark("drop")
        store.drop_oldest()
        after = state(store)
    done = [0] * len(fs.ops)
    with pytest.raises((AssertionError, CclogError)):
        crash_everywhere(tmp_path, fs.ops, begin, [before, after], done, 0, modes=len(MODES))
