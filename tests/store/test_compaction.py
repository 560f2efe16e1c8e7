"""Compaction and retention in the store: seal(), rewrite(), drop_oldest(), format v2."""

import json
import shutil
from pathlib import Path

import pytest

import cclogfs
from cclogfs.errors import CorruptionError, DamagedError, InvalidInputError, StoreError, StoreFailedError
from cclogfs.store.format import MANIFEST, RecordFlag, pack_manifest, unpack_manifest
from cclogfs.store.fs import FileSystem, RecordingFileSystem
from cclogfs.store import check_store
from cclogfs.store import Replacement
from _rewrite import leftovers, state
from helpers import append, flip

OPTS = dict(sync_every_ms=None, segment_records=3)
GOLDEN = Path(__file__).parent.parent / "golden"


def make(path, n=10, **opts):
    """A store of n windows (5 messages each, /odom and /tf alternating), every one sealed."""
    store = cclogfs.open_store(path, create=True, **(OPTS | opts))
    for i in range(n):
        store.put_window(("/tf", "/odom")[i % 2], [(i * 100 + k, json.dumps({"i": i, "x": k * 0.25})) for k in range(5)],
                         meta={"i": i})  # fmt: skip
    store.seal()
    return store


def files(path):
    return {p.name: p.read_bytes() for p in sorted(Path(path).iterdir())}


def aged(window):
    msgs = list(window.messages())[::2]
    return Replacement([(t, '{"r":1}') for t, _ in msgs], dict(window.meta, aged={"abs": 0.5}), flags=RecordFlag.AGED)


def test_seal_on_demand(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True, **OPTS) as store:
        assert store.seal() is False  # nothing to seal
        store.put_window("/a", [(1, "1")])
        assert store.seal() is True
        assert [s.first_seq for s in store.sealed] == [0] and store.active.first_seq == 1
        assert store.manifest["format_version"] == 3  # written by this version (records carry a synced length)
    with cclogfs.open_store(tmp_path / "s", **OPTS) as store:
        assert store.recovery.clean and [w.seq for w in store.query()] == [0]


def test_rewrite_replaces_downsamples_and_keeps(tmp_path):
    with make(tmp_path / "s") as store:
        old = state(store)
        report = store.rewrite(lambda w: aged(w) if w.name == "/odom" else None)
        assert report.segments == [0, 3, 6, 9] and (report.replaced, report.kept) == (5, 5)
        assert report.before["/odom"]["messages"] == 25 and report.after["/odom"]["messages"] == 15
        assert report.before["/tf"] == report.after["/tf"]
        new = state(store)
        assert store.manifest["format_version"] == 3  # written by this version
        assert [s.get("gen") for s in store.manifest["segments"]] == [1, 1, 1, 1]
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert state(store) == new
        for before, after in zip(old, new):
            if before[1] == "/tf":
                assert after == before
            else:
                seq, name, start, end, meta, flags, messages = after
                assert (seq, name, start, end) == before[:4] and flags == RecordFlag.AGED
                assert meta == dict(before[4], aged={"abs": 0.5})
                assert [t for t, _ in messages] == [t for t, _ in before[6]][::2]
        assert {w.seq: w.aged for w in store.query("/odom")} == {s: {"abs": 0.5} for s in (1, 3, 5, 7, 9)}
        assert [w.aged for w in store.query("/tf")] == [None] * 5
        assert store.streams()["/odom"]["aged"] == 5 and store.streams()["/tf"]["aged"] == 0
    assert sorted(files(tmp_path / "s")) == ["00000000000000000000-1.idx", "00000000000000000000-1.seg",
                                             "00000000000000000003-1.idx", "00000000000000000003-1.seg",
                                             "00000000000000000006-1.idx", "00000000000000000006-1.seg",
                                             "00000000000000000009-1.idx", "00000000000000000009-1.seg",
                                             "00000000000000000010.idx", "00000000000000000010.seg",  # a checkpoint index
                                             "LOCK", MANIFEST, "RESERVE"]  # fmt: skip


def test_a_segment_whose_records_are_all_kept_is_not_rewritten(tmp_path):
    with make(tmp_path / "s") as store:
        before = files(tmp_path / "s")
        report = store.rewrite(lambda w: None)
        assert report.segments == [] and files(tmp_path / "s") == before
        store.rewrite(lambda w: aged(w) if w.seq == 4 else None)
        assert [s.get("gen", 0) for s in store.manifest["segments"]] == [0, 1, 0, 0]
        store.rewrite(lambda w: aged(w) if w.seq == 4 else None, segments=[3])  # again: generation 2
        assert [s.get("gen", 0) for s in store.manifest["segments"]] == [0, 2, 0, 0]
        assert (tmp_path / "s" / "00000000000000000003-2.seg").exists()
        assert not (tmp_path / "s" / "00000000000000000003-1.seg").exists()
        with pytest.raises(InvalidInputError, match="no sealed segment starts at seq 4"):
            store.rewrite(lambda w: None, segments=[4])


BAD = {
    "starts before the record": lambda w: Replacement([(w.start_ns - 1, "1")], {}),
    "ends after the record": lambda w: Replacement([(w.end_ns + 1, "1")], {}),
    "no message": lambda w: Replacement([], {}),
    "not JSON": lambda w: Replacement([(w.start_ns, "{")], {}),
    "times decrease": lambda w: Replacement([(w.end_ns, "1"), (w.start_ns, "1")], {}),
    "a renamed stream (a tuple)": lambda w: ("/other", list(w.messages()), w.meta),
    "AGED without meta aged": lambda w: Replacement(list(w.messages()), {}, flags=RecordFlag.AGED),
    "an unknown flag": lambda w: Replacement(list(w.messages()), {}, flags=4),
    "meta not a dict": lambda w: Replacement(list(w.messages()), [1]),
    "unknown codec": lambda w: Replacement(list(w.messages()), {}, codec="nope"),
}


@pytest.mark.parametrize("why", sorted(BAD))
def test_a_bad_replacement_is_refused_and_changes_nothing(tmp_path, why):
    bad = BAD[why]
    with make(tmp_path / "s") as store:
        before, old = files(tmp_path / "s"), state(store)
        # Segments 0 and 3 are replaced fine (their new generations are written) before
        # the bad replacement of seq 7: nothing may survive of them.
        with pytest.raises(cclogfs.errors.CclogError) as err:
            store.rewrite(lambda w: bad(w) if w.seq == 7 else aged(w))
        assert "seq 7" in str(err.value) or why == "unknown codec"
        assert files(tmp_path / "s") == before and state(store) == old
        store.put_window("/a", [(10**6, "1")])  # the store still takes writes
    with cclogfs.open_store(tmp_path / "s", **OPTS) as store:
        assert store.recovery.clean and state(store)[:-1] == old


def test_an_error_in_the_callback_changes_nothing(tmp_path):
    def boom(w):
        if w.seq == 5:
            raise RuntimeError("callback failed")
        return aged(w)

    with make(tmp_path / "s") as store:
        before = files(tmp_path / "s")
        with pytest.raises(RuntimeError):
            store.rewrite(boom)
        assert files(tmp_path / "s") == before


def test_drop_oldest_moves_the_start_of_the_log(tmp_path):
    with make(tmp_path / "s") as store:
        old = state(store)
        d = store.drop_oldest()
        assert (d.first_seq, d.end_seq) == (0, 3) and d.streams["/tf"]["windows"] == 2 and d.bytes > 0
        assert store.first_seq == 3 and [w[0] for w in state(store)] == list(range(3, 10))
        assert state(store) == old[3:]
        assert store.dropped() == {"segments": 1, "streams": d.streams}
        while store.drop_oldest():
            pass
        assert store.first_seq == 10 and state(store) == [] and store.streams() == {}
        odom = store.dropped()["streams"]["/odom"]
        assert (odom["windows"], odom["messages"], odom["start_ns"], odom["end_ns"]) == (5, 25, 100, 904)
        assert store.put_window("/a", [(5, "1")]).seq == 10  # sequence numbers are never reused
        store.seal()
        assert store.drop_oldest().first_seq == 10
        assert store.drop_oldest() is None  # the active segment is never dropped
        assert store.put_window("/a", [(6, "2")]).seq == 11
    with cclogfs.open_store(tmp_path / "s", **OPTS) as store:
        assert store.recovery.clean and [w.seq for w in store.query()] == [11]
        assert store.first_seq == 11 and store.dropped()["segments"] == 5
    assert sorted(files(tmp_path / "s")) == ["00000000000000000011.idx", "00000000000000000011.seg", "LOCK",
                                             MANIFEST, "RESERVE"]  # the .idx: the active segment's checkpoint index
    report = check_store(str(tmp_path / "s"))
    assert not report.findings and report.records == 1


def test_fsck_is_clean_after_rewrite_and_drop_and_deep_reads_aged_records(tmp_path):
    with make(tmp_path / "s") as store:
        store.rewrite(lambda w: aged(w) if w.seq % 3 else None)
        store.drop_oldest()
        store.put_window("/a", [(10**6, "1")])
    report = check_store(str(tmp_path / "s"), deep=True)
    assert not report.findings, [str(f) for f in report.findings]
    assert (report.records, report.decoded, report.aged) == (8, 8, 4)  # seqs 4 5 7 8


def test_fsck_says_when_the_manifest_miscounts_aged_windows(tmp_path):
    with make(tmp_path / "s") as store:
        store.rewrite(lambda w: aged(w) if w.seq == 1 else None)
    path = tmp_path / "s" / MANIFEST
    body = unpack_manifest(path.read_bytes())
    del body["segments"][0]["aged"]
    path.write_bytes(pack_manifest(body))
    (finding,) = check_store(str(tmp_path / "s")).errors
    assert "aged windows" in finding.what


def test_leftovers_are_warnings_for_fsck_and_removed_by_the_writer(tmp_path):
    with make(tmp_path / "s") as store:
        store.rewrite(lambda w: aged(w) if w.seq == 4 else None)
        store.drop_oldest()
    s = tmp_path / "s"
    # What interrupted steps leave: an unnamed new generation, the old generation, a dropped segment.
    shutil.copy(s / "00000000000000000003-1.seg", s / "00000000000000000003-2.seg")
    shutil.copy(s / "00000000000000000003-1.idx", s / "00000000000000000003.idx")
    shutil.copy(s / "00000000000000000006.seg", s / "00000000000000000000.seg")
    with cclogfs.open_store(s, readonly=True) as reader:
        expected = state(reader)
        assert sorted(reader.recovery.leftovers) == ["00000000000000000000.seg", "00000000000000000003-2.seg",
                                                     "00000000000000000003.idx"]  # fmt: skip
    report = check_store(str(s))
    assert not report.errors and len(report.findings) == 3
    assert all("interrupted compaction" in f.what for f in report.findings)
    with cclogfs.open_store(s, **OPTS) as store:
        assert store.recovery.clean and state(store) == expected
        assert sorted(store.recovery.removed_files) == sorted(reader.recovery.leftovers)
        assert leftovers(s, store.manifest) == []
    assert not check_store(str(s)).findings


def test_a_failed_fsync_while_rewriting_leaves_the_store_unchanged_and_usable(tmp_path):
    # The new generation is not named yet (a full disk fails the same way): nothing live
    # changed, so the store removes it and goes on, instead of refusing every later write.
    fs = RecordingFileSystem()
    with make(tmp_path / "s", fs=fs) as store:
        old = state(store)
        fs.fail_fsync = True
        with pytest.raises(StoreError, match="rewriting failed before its commit.*unchanged"):
            store.rewrite(aged)
        fs.fail_fsync = False
        assert not [p.name for p in (tmp_path / "s").iterdir() if "-1." in p.name]
        assert state(store) == old
        store.put_window("/odom", [(10_000, "{}")])
        store.drop_oldest()
    with cclogfs.open_store(tmp_path / "s", **OPTS) as store:
        assert store.recovery.leftovers == [] and 10_000 in [w.start_ns for w in store.query()]


def test_compaction_needs_the_writer(tmp_path):
    make(tmp_path / "s").close()
    with cclogfs.open_store(tmp_path / "s", readonly=True) as reader:
        for call in (reader.seal, reader.drop_oldest, lambda: reader.rewrite(lambda w: None)):
            with pytest.raises(StoreError, match="read-only"):
                call()


def test_a_reader_keeps_its_generation_until_refresh(tmp_path):
    with make(tmp_path / "s") as store:
        reader = cclogfs.open_store(tmp_path / "s", readonly=True)
        early = next(reader.query())  # handed out before the rewrite, not yet read
        old = state(store)
        store.rewrite(lambda w: aged(w))
        store.drop_oldest()
        new = state(store)
        # The old generation's files are deleted but still open: the reader's snapshot holds,
        # its indexes rebuilt from the open segments.
        assert state(reader) == old
        assert list(early.messages()) == old[0][6]
        reader.refresh()
        assert state(reader) == new and reader.first_seq == 3
        reader.close()


class RaceFileSystem(FileSystem):
    """A reader's file system that lets a writer compact right after each manifest read."""

    def __init__(self, after_manifest):
        self.after_manifest = after_manifest

    def read_file(self, path, limit=None):
        data = super().read_file(path, limit)
        if path.endswith(MANIFEST) and self.after_manifest:
            self.after_manifest.pop(0)()
        return data


def test_a_reader_racing_a_compaction_rereads_the_manifest(tmp_path):
    with make(tmp_path / "s") as store:
        steps = [lambda: store.rewrite(lambda w: aged(w) if w.seq == 1 else None)]
        with cclogfs.open_store(tmp_path / "s", readonly=True, fs=RaceFileSystem(steps)) as reader:
            assert state(reader) == state(store)
            steps += [lambda: store.rewrite(lambda w: aged(w) if w.seq == 2 else None), store.drop_oldest]
            reader.refresh()
            assert state(reader) == state(store)
            assert not steps  # every compaction ran between a manifest read and the files' opening


def test_a_version_1_store_opened_and_closed_stays_byte_for_byte(tmp_path):
    shutil.copytree(GOLDEN / "store_v1", tmp_path / "s")
    before = files(tmp_path / "s")
    with cclogfs.open_store(tmp_path / "s", sync_every_ms=None, segment_age_s=1e12):
        pass  # (its active segment is older than the default age limit: it would be sealed)
    after = files(tmp_path / "s")
    del after["LOCK"], after["RESERVE"]
    assert after == before
    with cclogfs.open_store(tmp_path / "s", **OPTS) as store:
        store.put_window("/a", [(1, "1")])
        store.seal()
        # Its new record carries a synced length (record version 2): older readers must refuse.
        assert unpack_manifest((tmp_path / "s" / MANIFEST).read_bytes())["format_version"] == 3


def test_an_unknown_format_version_is_refused_naming_file_and_field(tmp_path):
    make(tmp_path / "s").close()
    path = tmp_path / "s" / MANIFEST
    path.write_bytes(pack_manifest(unpack_manifest(path.read_bytes()) | {"format_version": 4}))
    for opts in ({"readonly": True}, {}):
        with pytest.raises(StoreError, match=r"MANIFEST: field format_version is 4"):
            cclogfs.open_store(tmp_path / "s", **opts)


def test_a_missing_generation_is_corruption(tmp_path):
    with make(tmp_path / "s") as store:
        store.rewrite(lambda w: aged(w) if w.seq == 1 else None)
    (tmp_path / "s" / "00000000000000000000-1.seg").unlink()
    with pytest.raises(CorruptionError, match="00000000000000000000-1.seg, which is missing"):
        cclogfs.open_store(tmp_path / "s", readonly=True)


def test_a_record_of_unknown_flags_is_copied_by_a_rewrite(tmp_path):
    from helpers import patch_header

    opts = OPTS | {"segment_records": 100}
    with cclogfs.open_store(tmp_path / "s", create=True, **opts) as store:
        for i in range(3):
            store.put_window("/a", [(i, "1"), (i, "2")])
        offsets = {w.seq: w.offset for w in store.query()}
    patch_header(tmp_path / "s" / "00000000000000000000.seg", offsets[1], flags=4)  # a newer writer's flag
    with cclogfs.open_store(tmp_path / "s", **opts) as store:
        assert [w.seq for w in store.query()] == [0, 2] and store.recovery.skipped
        store.seal()
        store.rewrite(lambda w: Replacement([(w.start_ns, "3")], {}))
        assert [list(w.messages()) for w in store.query()] == [[(0, "3")], [(2, "3")]]
    report = check_store(str(tmp_path / "s"))
    assert not report.errors and report.records == 2
    assert [f.what for f in report.findings] == ["unknown record flags, skipped"]


@pytest.mark.parametrize("damage", ["flip", "grow"])
def test_a_damaged_segment_is_refused_not_copied(tmp_path, damage):
    make(tmp_path / "s").close()
    seg = tmp_path / "s" / "00000000000000000003.seg"
    if damage == "flip":
        flip(seg, -5)  # in the last record's payload
    else:
        append(seg, b"\0" * 10)
    with cclogfs.open_store(tmp_path / "s", **OPTS) as store:
        before = files(tmp_path / "s")
        with pytest.raises(CorruptionError, match="00000000000000000003.seg.*cannot be rewritten"):
            store.rewrite(aged)
        assert files(tmp_path / "s") == before
        store.rewrite(aged, segments=[0, 6])  # the intact segments still can be


# -- found in review: an interrupt after the commit, and readers racing a compaction ------


class Interrupted(BaseException):
    """Stands for KeyboardInterrupt (which would stop pytest itself)."""


class FailAfterManifestRename(FileSystem):
    """Raises (as Ctrl-C would) in the directory fsync right after the manifest rename."""

    armed = renamed = False

    def rename(self, src, dst):
        super().rename(src, dst)
        self.renamed = self.armed and dst.endswith(MANIFEST)

    def fsync_dir(self, path):
        if self.renamed:
            self.armed = self.renamed = False
            raise Interrupted
        super().fsync_dir(path)


@pytest.mark.parametrize("step", ["rewrite", "drop"])
def test_interrupt_after_the_commit_keeps_every_file_the_manifest_names(tmp_path, step):
    fs = FailAfterManifestRename()
    store = cclogfs.open_store(tmp_path / "s", create=True, fs=fs, **OPTS)
    for i in range(6):
        store.put_window("/odom", [(i * 100 + k, json.dumps({"x": 1.25 + k})) for k in range(3)])
    store.seal()
    fs.armed = True
    with pytest.raises(StoreFailedError, match="at its commit"):
        store.rewrite(aged) if step == "rewrite" else store.drop_oldest()
    with pytest.raises(StoreFailedError):
        store.put_window("/odom", [(10_000, "{}")])
    store.close()
    # The rename happened, so the new state is the store; opening finds every file it names.
    with cclogfs.open_store(tmp_path / "s") as s:
        windows = list(s.query())
        if step == "rewrite":
            assert len(windows) == 6 and all(w.aged == {"abs": 0.5} for w in windows)
        else:
            assert s.first_seq == 3 and [w.seq for w in windows] == [3, 4, 5]
    assert not check_store(str(tmp_path / "s"), deep=True).errors


def test_open_deletes_no_leftover_while_a_named_segment_is_missing(tmp_path):
    store = make(tmp_path / "s")
    store.rewrite(aged, segments=[0])
    store.close()
    named = tmp_path / "s" / "00000000000000000000-1.seg"
    old = tmp_path / "s" / "00000000000000000000.seg"
    named.rename(old)  # as if the new generation were lost: only the old one is left
    before = files(tmp_path / "s")
    with pytest.raises(CorruptionError, match="missing"):
        cclogfs.open_store(tmp_path / "s")
    assert files(tmp_path / "s") == before  # the only copy left is not deleted as a leftover


@pytest.mark.parametrize("when", ["before listdir", "after listdir"])
def test_a_reader_opening_during_a_compaction_sees_one_consistent_store(tmp_path, when):
    writer = cclogfs.open_store(tmp_path / "s", create=True, sync_every_ms=None)
    for i in range(4):
        writer.put_window("/odom", [(i * 10 + k, json.dumps({"x": 1.5 + k})) for k in range(3)])
    writer.sync()  # all in the unsealed tail, which the race seals and rewrites

    class Racy(FileSystem):
        fired = False

        def listdir(self, path):
            names = super().listdir(path) if when == "after listdir" else None
            if not self.fired:
                self.fired = True
                writer.seal()
                writer.rewrite(aged)
            return names if names is not None else super().listdir(path)

    reader = cclogfs.open_store(tmp_path / "s", readonly=True, fs=Racy())
    assert [w.seq for w in reader.query()] == [0, 1, 2, 3]
    assert not reader.recovery.problems
    writer.close()


def test_put_window_refuses_the_reserved_aged_meta_key(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        with pytest.raises(InvalidInputError, match="'aged' is reserved"):
            store.put_window("/odom", [(1, "{}")], meta={"aged": "no"})
        assert list(store.query()) == []


def test_open_keeps_the_old_generation_while_the_named_one_is_cut_short(tmp_path):
    store = make(tmp_path / "s")
    old_files = {n: (tmp_path / "s" / n).read_bytes() for n in ("00000000000000000000.seg", "00000000000000000000.idx")}
    store.rewrite(aged, segments=[0])
    store.close()
    for name, data in old_files.items():  # as if the crash came before the old files went
        (tmp_path / "s" / name).write_bytes(data)
    new = tmp_path / "s" / "00000000000000000000-1.seg"
    new.write_bytes(new.read_bytes()[:-10])  # and the new generation lost its end
    # A cut sealed segment is damage: a writer refuses to open (it would append past it),
    # a reader opens and refuses the query; either way the old generation stays.
    with pytest.raises(DamagedError, match="00000000000000000000-1.seg"):
        cclogfs.open_store(tmp_path / "s", **OPTS)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        with pytest.raises(CorruptionError):
            list(s.query())
    assert all((tmp_path / "s" / name).read_bytes() == data for name, data in old_files.items())


_KILLED_DROP = """
import os, signal, sys
import cclogfs
from cclogfs.store.fs import FileSystem

class Killed(FileSystem):
    def rename(self, src, dst):
        if src.endswith("MANIFEST.tmp") and sys.argv[2] == "before":
            os.kill(os.getpid(), signal.SIGKILL)  # the copies synced, the drop not committed
        super().rename(src, dst)
        if src.endswith("MANIFEST.tmp"):
            os.kill(os.getpid(), signal.SIGKILL)  # committed, the old files not yet deleted

store = cclogfs.open_store(sys.argv[1], sync_every_ms=None, segment_records=3, fs=Killed())
store.drop_oldest(carry=["/tf"])
"""


def _tf(path, copies=False):
    with cclogfs.open_store(path, readonly=True) as s:
        return [(w.seq, w.meta, list(w.messages())) for w in s.query("/tf", copies=copies)]


@pytest.mark.parametrize("when", ["before", "after"])
def test_drop_oldest_carries_a_streams_windows_once_even_when_killed_around_its_commit(tmp_path, when):
    """Retention's carry (FORMAT.md, "Compaction and retention"): the windows of the streams
    named are put again before the drop commits, so none is lost; a kill -9 before the
    commit leaves them twice (queries show them once: the copies only with `copies`), and
    the next drop does not carry them a third time."""
    import subprocess
    import sys

    make(tmp_path / "s").close()
    before = _tf(tmp_path / "s")  # seqs 0, 2 in the oldest segment (0..2)
    proc = subprocess.run([sys.executable, "-c", _KILLED_DROP, str(tmp_path / "s"), when])
    assert proc.returncode == -9
    after = _tf(tmp_path / "s", copies=True)
    copies = [(meta, msgs) for seq, meta, msgs in after if seq >= 10]
    assert copies == [(dict(meta, carried={"seq": seq}), msgs) for seq, meta, msgs in before if seq < 3]
    assert [seq for seq, _m, _w in after if seq < 10] == ([0, 2, 4, 6, 8] if when == "before" else [4, 6, 8])
    # Each window once: the originals while they are there, else their copies.
    assert [seq for seq, _m, _w in _tf(tmp_path / "s")] == ([0, 2, 4, 6, 8] if when == "before" else [10, 11, 4, 6, 8])
    assert not check_store(str(tmp_path / "s")).errors
    with cclogfs.open_store(tmp_path / "s", **OPTS) as store:
        gone = store.drop_oldest(carry=["/tf"])
        assert (gone.first_seq, gone.carried) == ((0, ["/tf"]) if when == "before" else (3, ["/tf"]))
        assert "/tf" not in gone.streams and "/tf" not in store.dropped()["streams"]
        assert "/odom" in store.dropped()["streams"]
    final = _tf(tmp_path / "s")
    assert sorted(origin for origin in (m.get("carried", {}).get("seq", s) for s, m, _w in final)) == [0, 2, 4, 6, 8]
    assert sorted(msgs for _s, _m, msgs in final) == sorted(msgs for _s, _m, msgs in before)
    assert not check_store(str(tmp_path / "s"), deep=True).findings
