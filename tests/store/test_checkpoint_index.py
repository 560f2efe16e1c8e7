"""Issue 14: a reader of a cleanly closed store takes the active segment's records from the
index that close wrote instead of scanning the segment, and only on the segment's first use
(opening reads none of them); after a crash it scans only what was written after the last
clean close; an index that disagrees makes it scan it all, and damage that scan finds below
the checkpoint is declared as an open that scans declares it."""

import json
import shutil

import pytest

import cclogfs
from cclogfs.store import check_store, recovery
from cclogfs.store.format import SEGMENT_HEADER_SIZE
from cclogfs.store.index import SegmentIndex
from helpers import SEG, flip, forge_index_offsets, make_store

IDX = SEG.replace(".seg", ".idx")


@pytest.fixture
def scans(monkeypatch):
    """Where each scan of a tail segment started: (offset, seq)."""
    starts = []
    real = recovery.scan

    def spy(seg, *, salvage=False, start=None):
        starts.append(start or (SEGMENT_HEADER_SIZE, seg.first_seq))
        return real(seg, salvage=salvage, start=start)

    monkeypatch.setattr(recovery, "scan", spy)
    return starts


def windows(path, **opts):
    with cclogfs.open_store(path, readonly=True, **opts) as store:
        return [(w.seq, w.name, w.start_ns, w.end_ns, list(w.messages())) for w in store.query()]


def checkpoint(path):
    with cclogfs.open_store(path, readonly=True) as store:
        return store.manifest.checkpoint


def test_a_clean_close_is_opened_without_scanning_its_records(tmp_path, scans):
    make_store(tmp_path / "s", n=6)
    mark = checkpoint(tmp_path / "s")
    scans.clear()
    got = windows(tmp_path / "s")
    assert [w[0] for w in got] == list(range(6))
    assert scans == [(mark["synced"], 6)]  # a scan of nothing: the file ends at the checkpoint
    assert scans == [((tmp_path / "s" / SEG).stat().st_size, 6)]
    scans.clear()
    assert windows(tmp_path / "s", verify=True) == got  # fsck's open scans it whole
    assert scans == [(SEGMENT_HEADER_SIZE, 0)]
    assert not check_store(str(tmp_path / "s")).findings


def test_after_a_crash_only_what_followed_the_last_clean_close_is_scanned(tmp_path, scans):
    make_store(tmp_path / "s", n=4)
    mark = checkpoint(tmp_path / "s")
    store = cclogfs.open_store(tmp_path / "s", sync_every_ms=None)
    for i in range(4, 7):
        store.put_window("/b", [(i * 10, json.dumps({"i": i}))])
    store.sync()
    shutil.copytree(tmp_path / "s", tmp_path / "crashed")  # the disk as a crash now leaves it
    store.close()
    scans.clear()
    got = windows(tmp_path / "crashed")
    assert scans == [(mark["synced"], 4)]
    assert [(w[0], w[1]) for w in got] == [(0, "/a"), (1, "/a"), (2, "/a"), (3, "/a"), (4, "/b"), (5, "/b"), (6, "/b")]
    assert got == windows(tmp_path / "s") == windows(tmp_path / "crashed", verify=True)


@pytest.mark.parametrize("spoil", ["missing", "flipped", "forged", "stale"])
def test_an_index_that_disagrees_makes_the_reader_scan(tmp_path, scans, spoil):
    make_store(tmp_path / "s", n=5)
    expected = windows(tmp_path / "s")
    idx = tmp_path / "s" / IDX
    if spoil == "missing":
        idx.unlink()
    elif spoil == "flipped":
        flip(idx, 40)
    elif spoil == "forged":  # valid checksum, every entry points at another record
        forge_index_offsets(tmp_path / "s", SEG)
    else:  # an index of fewer records, as a close cut short before its manifest leaves
        data = idx.read_bytes()
        old = SegmentIndex.decode(data, 0, (tmp_path / "s" / SEG).stat().st_size)
        rows = old.rows()[:3]
        idx.write_bytes(SegmentIndex.build(rows).encode(0, rows[-1][5] + rows[-1][6]))
    mark = checkpoint(tmp_path / "s")
    scans.clear()
    assert windows(tmp_path / "s") == expected
    # Open scans what followed the checkpoint (nothing); the first query finds the index
    # wrong and scans the segment whole. Without an index there is nothing to defer to.
    assert scans == ([] if spoil == "missing" else [(mark["synced"], 5)]) + [(SEGMENT_HEADER_SIZE, 0)]
    findings = [f.where for f in check_store(str(tmp_path / "s")).findings]
    # Stale (another size than the checkpoint's) is what a close cut short leaves: no finding.
    assert findings == ([IDX] if spoil in ("flipped", "forged") else [])


def test_opening_reads_no_record_below_the_checkpoint_and_the_first_use_loads_them(tmp_path, monkeypatch):
    make_store(tmp_path / "s", n=5)
    decoded = []
    real = SegmentIndex.decode
    monkeypatch.setattr(SegmentIndex, "decode", lambda *a: decoded.append(a[1]) or real(*a))
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert decoded == [] and store.segment_count() == 1
        assert [w.seq for w in store.query("/a", 20, 30)] == [1, 2, 3]
        assert decoded == [0]  # the index of segment 0, once
        assert [w.seq for w in store.query()] == [0, 1, 2, 3, 4]
        assert decoded == [0]


@pytest.mark.parametrize("index", ["kept", "flipped"])
def test_damage_below_the_checkpoint_found_on_first_use_is_declared(tmp_path, index):
    # With the index spoilt, the first use scans the segment and finds the damaged record:
    # a query refuses and damage() names it, as after an open that scans (verify=True).
    from cclogfs.errors import CorruptionError, DamagedError

    recs = make_store(tmp_path / "s", n=5)
    _seq, off, length = recs[2]
    flip(tmp_path / "s" / SEG, off + length - 5)
    if index == "flipped":
        flip(tmp_path / "s" / IDX, 40)
    with cclogfs.open_store(tmp_path / "s", readonly=True, verify=True) as store:
        scanned = store.damage()
    assert [(d["first_seq"], d["end_seq"]) for d in scanned] == [(2, 3)]
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        if index == "kept":  # the index holds: the record is checked when read, as a sealed one's
            assert store.damage() == []
            with pytest.raises(CorruptionError, match="payload checksum mismatch"):
                [list(w.messages()) for w in store.query()]
            return
        with pytest.raises(DamagedError):
            list(store.query())
        assert store.damage() == scanned
        assert [w.seq for w in store.query(skip_damaged=True)] == [0, 1, 3, 4]


def test_a_store_closed_by_an_older_version_has_no_index_and_is_scanned(tmp_path, scans):
    make_store(tmp_path / "s", n=3)
    (tmp_path / "s" / IDX).unlink()
    scans.clear()
    assert [w[0] for w in windows(tmp_path / "s")] == [0, 1, 2]
    assert scans == [(SEGMENT_HEADER_SIZE, 0)]
    with cclogfs.open_store(tmp_path / "s") as store:  # the writer writes one at its close
        store.put_window("/a", [(100, "1")])
    scans.clear()
    assert [w[0] for w in windows(tmp_path / "s")] == [0, 1, 2, 3]
    assert scans == [((tmp_path / "s" / SEG).stat().st_size, 4)]


def test_damage_in_a_checkpointed_segment_is_refused_on_read_and_found_by_fsck(tmp_path):
    # The reader trusts the checkpoint as it trusts a sealed segment: it reads nothing at
    # open, and a damaged record raises when read, never returns changed messages.
    from cclogfs.errors import CorruptionError

    recs = make_store(tmp_path / "s", n=4)
    _seq, off, length = recs[2]
    flip(tmp_path / "s" / SEG, off + length - 5)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        (bad,) = [w for w in store.query() if w.seq == 2]
        with pytest.raises(CorruptionError, match="payload checksum mismatch"):
            list(bad.messages())
    assert [f.what for f in check_store(str(tmp_path / "s")).errors] != []
    with cclogfs.open_store(tmp_path / "s") as store:  # the writer scans: damage is named
        assert [(d["first_seq"], d["end_seq"]) for d in store.damage()] == [(2, 3)]
