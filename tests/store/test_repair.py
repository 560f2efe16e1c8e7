"""Issue 11: `fsck --repair` rebuilds, salvages and quarantines; idempotent; drops only on request."""

import random

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.store import check_store, repair_store
from cclogfs.store.fs import RecordingFileSystem
from crashsim import DiskModel
from helpers import SEG, flip, forge_index_offsets, make_store


def _messages(store, **kw):
    return {w.seq: (w.name, list(w.messages())) for w in store.query(**kw)}


def test_repair_salvages_a_side_file_back_into_the_store(tmp_path, capsys):
    # Item 1/9: an older version cut intact records into a side file; repair brings them back.
    recs = make_store(tmp_path / "s", n=5)
    data = (tmp_path / "s" / SEG).read_bytes()
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        want = {seq: m for seq, m in _messages(store).items() if seq >= 2}
    side = f"{SEG}.tail-{recs[2][1]}"
    (tmp_path / "s" / side).write_bytes(b"junk" + data[recs[2][1] + 4 :])  # its first record damaged
    assert main(["fsck", str(tmp_path / "s"), "--repair"]) == 4  # salvaged, the junk quarantined
    out = capsys.readouterr().out
    assert "salvaged 2 intact records" in out and "damage left: quarantine/" in out
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        salvaged = [w for w in store.query() if "salvaged" in w.meta]
        assert sorted(w.meta["salvaged"]["seq"] for w in salvaged) == [3, 4]
        assert all((w.name, list(w.messages())) == want[w.meta["salvaged"]["seq"]] for w in salvaged)
    assert main(["fsck", str(tmp_path / "s"), "--repair"]) == 4  # idempotent: nothing put twice
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert sum("salvaged" in w.meta for w in store.query()) == 2
    assert main(["fsck", str(tmp_path / "s")]) == 1  # quarantine is an error until resolved
    assert main(["fsck", str(tmp_path / "s"), "--repair", "--discard-damaged"]) == 1
    assert main(["fsck", str(tmp_path / "s"), "--repair"]) == 0
    assert not check_store(str(tmp_path / "s")).errors


def test_repair_names_sealed_damage_and_discard_lets_reads_through(tmp_path, capsys):
    # Item 2: damage in a sealed segment, index gone: repair names it; reads are then exact.
    make_store(tmp_path / "s", n=9, segment_records=3)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        (w,) = [w for w in store.query() if w.seq == 4]
        before = _messages(store)
    flip(tmp_path / "s" / "00000000000000000003.seg", w.offset + w.stored_bytes - 5)
    (tmp_path / "s" / "00000000000000000003.idx").unlink()
    assert repair_store(str(tmp_path / "s")).exit_code == 4
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        (d,) = store.damage()
        assert (d["first_seq"], d["end_seq"]) == (4, 5)
        with pytest.raises(cclogfs.errors.DamagedError):
            list(store.query())
        assert _messages(store, skip_damaged=True) == {k: v for k, v in before.items() if k != 4}
    assert repair_store(str(tmp_path / "s"), discard_damaged=True).exit_code == 1
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert _messages(store) == {k: v for k, v in before.items() if k != 4}
    assert main(["fsck", str(tmp_path / "s")]) == 0


def test_repair_rebuilds_a_forged_index(tmp_path):
    # Item 10: an index with a valid checksum but wrong offsets is rebuilt from the segment.
    make_store(tmp_path / "s", n=6, segment_records=3)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        before = _messages(store)
    forge_index_offsets(tmp_path / "s", SEG)
    report = repair_store(str(tmp_path / "s"))
    assert report.exit_code == 1 and any("rebuilt index" in a for a in report.actions)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert _messages(store) == before


def test_repair_is_crash_safe(tmp_path):
    # A crash at any operation of a repair leaves a store the next repair finishes.
    recs = make_store(tmp_path / "s", n=5)
    data = (tmp_path / "s" / SEG).read_bytes()
    (tmp_path / "s" / f"{SEG}.tail-{recs[2][1]}").write_bytes(b"junk" + data[recs[2][1] + 4 :])
    base = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir() if p.is_file()}
    fs = RecordingFileSystem()
    repair_store(str(tmp_path / "s"), fs=fs)
    rng = random.Random(1)
    for k in range(0, len(fs.ops), max(1, len(fs.ops) // 25)):
        model = DiskModel()
        for name, content in base.items():  # the store as it was, all durable
            model.apply(("create", name))
            model.apply(("write", name, 0, content))
            model.apply(("fsync", name))
        model.apply(("fsync_dir", str(tmp_path / "s")))
        for op in fs.ops[:k]:
            model.apply(op)
        img = tmp_path / f"img{k}"
        img.mkdir()
        for name, content in model.image(rng, "lost").items():
            (img / name).write_bytes(content)
        repair_store(str(img))
        repair_store(str(img), discard_damaged=True)
        with cclogfs.open_store(img, readonly=True) as store:
            got = [w for w in store.query()]
            assert sorted(w.seq for w in got if "salvaged" not in w.meta) == [0, 1, 2, 3, 4]
            assert sorted(w.meta["salvaged"]["seq"] for w in got if "salvaged" in w.meta) == [3, 4]  # once each


def test_repair_rebuilds_a_damaged_manifest_from_the_segments(tmp_path):
    make_store(tmp_path / "s", n=9, segment_records=3)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        before = _messages(store)
    flip(tmp_path / "s" / "MANIFEST", 20)
    with pytest.raises(cclogfs.errors.CorruptionError, match="MANIFEST"):
        cclogfs.open_store(tmp_path / "s")
    report = repair_store(str(tmp_path / "s"))
    assert report.exit_code == 4 and any("rebuilt MANIFEST" in a for a in report.actions)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert _messages(store) == before and len(store.sealed) == 3
    assert repair_store(str(tmp_path / "s"), discard_damaged=True).exit_code == 1
    assert not check_store(str(tmp_path / "s"), deep=True).findings
