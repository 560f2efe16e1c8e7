"""The parts of a split window (issue 16; FORMAT.md "Record flags", "Splitting"): every
part but the last is flagged PART, a put's parts are synced as one unit, readers never show
a put whose last part is missing, fsck names one, and compaction keeps windows split."""

import json
import time

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import DamagedError, InvalidInputError, StoreFailedError
from cclogfs.store import Replacement, check_store, encode, segment
from cclogfs.store.format import RecordFlag
from cclogfs.store.fs import RecordingFileSystem
from cclogfs.store.store import Store
from helpers import SEG, patch_header

PART, AGED = int(RecordFlag.PART), int(RecordFlag.AGED)


def _window(n=60, t0=0):
    return [(t0 + i, json.dumps({"i": i, "x": i / 7, "pad": "p" * (i % 40)})) for i in range(n)]


@pytest.fixture
def small_parts(monkeypatch):
    """Records of at most 950 bytes of window: a 60-message window is 5 parts."""
    monkeypatch.setattr(encode, "MAX_RECORD_RAW", 950)


def _flags(path, **opts):
    with cclogfs.open_store(path, readonly=True, **opts) as store:
        return [(w.seq, w.name, w.flags) for w in sorted(store.query(skip_damaged=True), key=lambda w: w.seq)]


def test_every_part_but_the_last_is_flagged(tmp_path, small_parts):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/b", [(0, "1")])
        receipt = store.put_window("/a", _window(), meta={"w": 1})
    assert receipt.records == 5
    assert _flags(tmp_path / "s") == [(0, "/b", 0)] + [(s, "/a", PART) for s in range(1, 5)] + [(5, "/a", 0)]


# -- one unit: no group commit, no seal between the parts ------------------------------------


def _segment_ops(fs):
    return [op[0] for op in fs.ops if op[0] in ("write", "fsync") and op[1].endswith(".seg")]


@pytest.mark.parametrize("policy", [dict(sync_every_ms=0, sync_every_bytes=None),  # every put
                                    dict(sync_every_ms=None, sync_every_bytes=1),  # by size
                                    dict(sync_every_ms=1, sync_every_bytes=None)])  # by time, the thread too
def test_no_group_commit_falls_between_the_parts_of_a_put(tmp_path, small_parts, monkeypatch, policy):
    monkeypatch.setattr(segment, "WRITE_BUFFER", 1)  # each part handed to the OS alone
    append = Store._append

    def slow(self, name, enc, **kw):  # the background thread's timer runs out between the parts
        time.sleep(0.01)
        return append(self, name, enc, **kw)

    monkeypatch.setattr(Store, "_append", slow)
    fs = RecordingFileSystem()
    with cclogfs.open_store(tmp_path / "s", create=True, fs=fs, **policy) as store:
        del fs.ops[:]
        store.put_window("/a", _window())
        ops = _segment_ops(fs)
    assert ops[:6] == ["write"] * 5 + ["fsync"], ops  # the old writer: write, fsync, write, fsync...


def test_a_full_segment_is_sealed_after_the_put_never_between_its_parts(tmp_path, small_parts):
    with cclogfs.open_store(tmp_path / "s", create=True, segment_records=2) as store:
        store.put_window("/b", [(0, "1")])
        store.put_window("/a", _window())  # seqs 1..5: five parts, though two records a segment
        store.put_window("/b", [(100, "2")])
        assert [(s.first_seq, s.end_seq) for s in store.sealed_segments()] == [(0, 6)]
    assert not check_store(str(tmp_path / "s"), deep=True).findings


def test_an_interrupt_between_the_parts_fails_the_store(tmp_path, small_parts, monkeypatch):
    # A later put after an unfinished one would turn it into damage once synced: nothing more is written.
    append = Store._append

    def interrupted(self, name, enc, **kw):
        if self.active.next_seq == 3:
            raise KeyboardInterrupt
        return append(self, name, enc, **kw)

    store = cclogfs.open_store(tmp_path / "s", create=True, sync_every_ms=None)
    store.put_window("/b", [(0, "1")])
    store.sync()
    monkeypatch.setattr(Store, "_append", interrupted)
    with pytest.raises(KeyboardInterrupt):
        store.put_window("/a", _window())
    monkeypatch.undo()
    with pytest.raises(StoreFailedError):
        store.put_window("/b", [(1, "2")])
    store.close()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert [w.seq for w in store.query()] == [0]
        assert store.put_window("/b", [(1, "2")]).seq == 1
    assert not check_store(str(tmp_path / "s")).findings


# -- readers during a split put ----------------------------------------------------------------


def test_a_reader_refreshing_between_the_parts_sees_only_whole_windows(tmp_path, small_parts, monkeypatch):
    monkeypatch.setattr(segment, "WRITE_BUFFER", 1)  # each part reaches the file before the next
    writer = cclogfs.open_store(tmp_path / "s", create=True, sync_every_ms=None, sync_every_bytes=None)
    writer.put_window("/b", [(0, "1")])
    reader = cclogfs.open_store(tmp_path / "s", readonly=True)
    seen = []
    append = Store._append

    def watched(self, name, enc, **kw):
        if self is writer:
            reader.refresh()
            seen.append(([w.seq for w in reader.query()], sum(1 for w in reader.query() for _ in w.messages())))
        return append(self, name, enc, **kw)

    monkeypatch.setattr(Store, "_append", watched)
    writer.put_window("/a", _window())
    monkeypatch.undo()
    reader.refresh()
    assert seen == [([0], 1)] * 5  # before each part: /b alone, never a prefix of /a's parts
    assert [w.seq for w in reader.query()] == list(range(6))
    assert sum(1 for w in reader.query() for _ in w.messages()) == 61
    reader.close()
    writer.close()


def test_a_reader_opening_at_any_byte_of_a_split_put_lists_whole_windows(tmp_path, small_parts):
    from test_reader_race import Growing

    with cclogfs.open_store(tmp_path / "s", create=True, sync_every_ms=None, sync_every_bytes=None) as writer:
        writer.put_window("/b", [(0, "1")])
        writer.put_window("/a", _window(), meta={"w": 1})
        writer.put_window("/b", [(100, "2")])
        writer.active.flush()
        full = writer.active.size
        writer._dirty = False  # no checkpoint: the reader scans the tail, as while recording
        counts = set()
        for visible in [*range(32, full, 37), full]:
            with cclogfs.open_store(tmp_path / "s", readonly=True, fs=Growing(visible, 0, full)) as reader:
                listed = [w.seq for w in reader.query()]
                assert listed in ([], [0], list(range(6)), list(range(7))), (visible, listed)
                counts.add(len(listed))
            report = check_store(str(tmp_path / "s"), fs=Growing(visible, 0, full))
            assert report.errors == [], (visible, report.errors)
        assert counts == {0, 1, 6, 7}


# -- fsck and repair of an unfinished put below the synced point (forged) ----------------------


def _offsets(path):
    with cclogfs.open_store(path, readonly=True) as store:
        return {w.seq: w.offset for w in store.query()}


def test_an_unfinished_put_below_the_synced_point_is_damage(tmp_path, small_parts, capsys):
    # No writer leaves one (it syncs only after a put's last part): a forged final part.
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True) as store:
        store.put_window("/b", [(0, "1")])
        store.put_window("/a", _window())  # seqs 1..5
    patch_header(path / SEG, _offsets(path)[5], flags=PART)  # the clean close's checkpoint covers it
    report = check_store(str(path))
    assert len(report.errors) == 1 and "seqs 1..5: unfinished put" in report.errors[0].what, report.findings
    assert main(["fsck", str(path)]) == 1
    with pytest.raises(DamagedError, match="unfinished put"):
        with cclogfs.open_store(path, readonly=True, verify=True) as store:
            list(store.query())
    assert _flags(path, verify=True) == [(0, "/b", 0)]  # skip_damaged: never the parts
    capsys.readouterr()
    assert main(["fsck", "--repair", str(path)]) == 4  # named in the manifest, left until discarded
    with cclogfs.open_store(path) as store:
        assert [(d["first_seq"], d["end_seq"], d["reason"]) for d in store.damage()] == [(1, 6, "unfinished put")]
        assert store.put_window("/b", [(200, "2")]).seq == 6  # the parts' seqs are never reused
    assert main(["fsck", "--repair", "--discard-damaged", str(path)]) == 1
    assert main(["fsck", str(path)]) == 0
    assert [s for s, _n, _f in _flags(path)] == [0, 6]


@pytest.mark.parametrize("then", ["another stream", "another meta", "an earlier stamp"])
def test_a_part_not_followed_by_its_continuation_is_damage(tmp_path, small_parts, then):
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True) as store:
        store.put_window("/a", _window(), meta={"w": 1})  # seqs 0..4
        if then == "another stream":
            store.put_window("/b", [(100, "1")])
        else:  # a window of the same stream after it: only its meta or its stamps tell
            t = 100 if then == "another meta" else 3
            store.put_window("/a", [(t, "1")], meta={"w": 2 if then == "another meta" else 1})
    patch_header(path / SEG, _offsets(path)[4], flags=PART)
    with cclogfs.open_store(path) as store:
        (damage,) = store.damage()
        assert (damage["first_seq"], damage["end_seq"], damage["reason"]) == (0, 5, "unfinished put")
        assert [w.seq for w in store.query(skip_damaged=True)] == [5]  # the record after is intact
    assert check_store(str(path)).errors


def test_a_sealed_segment_ending_in_a_part_is_an_error_though_the_next_one_goes_on(tmp_path, small_parts):
    # The writer never seals between the parts of a put, so a part must be continued in its own
    # segment: a sealed segment ending in one is damage, whatever the next segment holds.
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True) as store:
        store.put_window("/a", _window(), meta={"w": 1})  # seqs 0..4, then sealed
        store.seal()
        store.put_window("/a", _window(5, t0=59), meta={"w": 1})  # seq 5: it would pass for a last part
    patch_header(path / SEG, _offsets(path)[4], flags=PART)
    report = check_store(str(path))
    assert any("unfinished put in a sealed segment" in f.what for f in report.errors), report.findings
    assert main(["fsck", "--repair", str(path)]) == 4
    with cclogfs.open_store(path) as store:
        assert [(d["first_seq"], d["end_seq"]) for d in store.damage()] == [(0, 5)]
        assert [w.seq for w in store.query(skip_damaged=True)] == [5]


# -- compaction and aging keep windows split --------------------------------------------------


def _split_store(path):
    with cclogfs.open_store(path, create=True, sync_every_ms=None) as store:
        store.put_window("/b", [(0, "1")])
        store.put_window("/a", _window(), meta={"w": 1})  # seqs 1..5
        store.put_window("/b", [(100, "2")])
        store.seal()


def _age(window):
    return Replacement(list(window.messages())[::2], dict(window.meta, aged={"downsampled": 2}), flags=AGED)


def test_compaction_keeps_the_parts_of_a_window(tmp_path, small_parts):
    path = tmp_path / "s"
    _split_store(path)
    with cclogfs.open_store(path, readonly=True) as store:
        before = [m for w in store.query("/a") for m in w.messages()]
    with cclogfs.open_store(path) as store:
        done = store.rewrite(lambda w: _age(w) if w.seq in (2, 5) else None)  # a middle part and the last
        assert done.replaced == 2
    assert _flags(path) == [(0, "/b", 0), (1, "/a", PART), (2, "/a", PART | AGED), (3, "/a", PART),
                            (4, "/a", PART), (5, "/a", AGED), (6, "/b", 0)]  # fmt: skip
    with cclogfs.open_store(path) as store:
        store.rewrite(_age)  # every record, the parts aged each alone
        got = [m for w in store.query("/a") for m in w.messages()]
    assert _flags(path)[1:6] == [(s, "/a", PART | AGED) for s in range(1, 5)] + [(5, "/a", AGED)]
    assert set(got) < set(before) and got == sorted(got)
    assert not check_store(str(path), deep=True).findings


@pytest.mark.parametrize("rep, why", [
    (lambda w: Replacement(list(w.messages()), {"w": 2}), "would break its split window: its meta differs"),
    (lambda w: Replacement(list(w.messages()), dict(w.meta), flags=PART), "the PART flag is not the caller's"),
])  # fmt: skip
def test_compaction_refuses_a_replacement_that_breaks_a_split_window(tmp_path, small_parts, rep, why):
    path = tmp_path / "s"
    _split_store(path)
    before = sorted(p.name for p in path.iterdir())
    with cclogfs.open_store(path) as store:
        with pytest.raises(InvalidInputError, match=why):
            store.rewrite(lambda w: rep(w) if w.seq == 3 else None)
    assert sorted(p.name for p in path.iterdir()) == before
    assert not check_store(str(path), deep=True).findings


def test_aging_a_store_of_split_windows_keeps_them_whole(tmp_path, small_parts):
    from cclogfs.upkeep.job import compact
    from cclogfs.upkeep.policy import Policy, parse_rule

    path = tmp_path / "s"
    _split_store(path)
    with cclogfs.open_store(path) as store:
        compact(store, policy=Policy([parse_rule("1e-2")]), older_than_ns=0)
    # Each part is a window to the policy: the last one ends the stream, so older_than 0
    # leaves it as it was, and the window is aged but for its last part (its chain holds).
    assert [f for _s, _n, f in _flags(path)][1:6] == [PART | AGED] * 4 + [0]
    assert not check_store(str(path), deep=True).findings
