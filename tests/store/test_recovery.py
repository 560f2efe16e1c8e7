"""cclogfs.store.recovery: what opening a store does to what a crash or an interrupted
compaction left, and what it must leave alone."""

import shutil

import cclogfs
from cclogfs.store.format import Reason, segment_name
from helpers import SEG, append, make_store, segment_files, seqs


def snapshot(path):
    return {p.name: p.read_bytes() for p in sorted(path.iterdir()) if p.name not in ("LOCK", "RESERVE")}


def torn_tail(path):
    """Append the first half of a copy of the last record: a put that a crash cut short
    before any sync covered it. Returns (segment, size before)."""
    recs = make_store(path)
    seg = path / SEG
    size = seg.stat().st_size
    _seq, off, length = recs[-1]
    append(seg, seg.read_bytes()[off : off + length // 2])
    return seg, size


def sealed_store(path):
    make_store(path, n=30, segment_bytes=4096, sync_every_bytes=1)
    return segment_files(path)


def test_a_clean_store_opens_with_nothing_to_report(tmp_path):
    make_store(tmp_path / "s")
    before = snapshot(tmp_path / "s")
    with cclogfs.open_store(tmp_path / "s") as store:
        r = store.recovery
        assert r.clean and (r.problems, r.skipped, r.removed_files, r.leftovers) == ([], [], [], [])
    assert snapshot(tmp_path / "s") == before


def test_a_torn_never_synced_tail_is_cut_and_reported(tmp_path):
    seg, size = torn_tail(tmp_path / "s")
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1, 2, 3]
        (p,) = store.recovery.problems
        assert (p.path, p.offset, p.reason) == (str(seg), size, Reason.TORN)
        assert not store.recovery.clean
        store.put_window("/a", [(1000, "{}")])  # the next put follows the cut directly
    with cclogfs.open_store(tmp_path / "s") as store:
        assert store.recovery.clean and seqs(store) == [0, 1, 2, 3, 4]
        assert [m for w in store.query() if w.seq == 4 for m in w.messages()] == [(1000, "{}")]


def test_leftovers_of_an_interrupted_compaction_are_removed_on_open(tmp_path):
    files = sealed_store(tmp_path / "s")
    first = files[0].name[:20]
    # An unnamed new generation of a sealed segment (the manifest was never switched to it).
    shutil.copy(files[0], tmp_path / "s" / f"{first}-1.seg")
    shutil.copy(files[0], tmp_path / "s" / f"{first}-3.seg")
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == list(range(30))
        assert sorted(store.recovery.leftovers) == [f"{first}-1.seg", f"{first}-3.seg"]
        assert sorted(store.recovery.removed_files) == [f"{first}-1.seg", f"{first}-3.seg"]
        assert store.recovery.clean  # leftovers are not damage
    assert segment_files(tmp_path / "s") == files


def test_a_stray_segment_before_the_manifests_end_is_reported_and_kept(tmp_path):
    sealed_store(tmp_path / "s")
    stray = tmp_path / "s" / segment_name(2)  # seq 2 lies inside the first sealed segment
    stray.write_bytes((tmp_path / "s" / SEG).read_bytes())
    with cclogfs.open_store(tmp_path / "s") as store:
        (p,) = store.recovery.problems
        assert (p.path, p.reason) == (str(stray), Reason.STRAY_SEGMENT)
        assert p.path not in [w.segment_path for w in store.query()]
        assert seqs(store) == list(range(30))
    assert stray.read_bytes() == (tmp_path / "s" / SEG).read_bytes()


def test_read_only_open_reports_but_changes_no_file(tmp_path):
    seg, size = torn_tail(tmp_path / "s")
    first = SEG[:20]
    shutil.copy(seg, tmp_path / "s" / f"{first}-2.seg")  # not named: a leftover
    before = snapshot(tmp_path / "s")
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert seqs(store) == [0, 1, 2, 3]
        assert [p.reason for p in store.recovery.problems] == [Reason.TORN]
        assert store.recovery.leftovers == [f"{first}-2.seg"] and store.recovery.removed_files == []
    assert snapshot(tmp_path / "s") == before
    assert seg.stat().st_size > size

