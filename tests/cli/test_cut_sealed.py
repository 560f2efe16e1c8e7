"""A sealed segment cut short since sealing (`truncate -s -3`) is damage, not a store no one can
open: readers get the intact records (with --skip-damaged), `fsck --repair` names the seqs the
cut lost (exit 4) and `--discard-damaged` drops them; the old code refused every open."""

import json
import os

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import DamagedError

SEG = "00000000000000000004.seg"  # seqs 4..7, sealed


def _store(path):
    with cclogfs.open_store(path, create=True, segment_records=4) as s:
        for w in range(10):
            s.put_window("/a", [(w * 1000 + i, json.dumps({"w": w, "i": i})) for i in range(3)])


def _record_offsets(path):
    with cclogfs.open_store(path, readonly=True) as s:
        return {w.seq: (w._offset, w._length) for w in s.query() if 4 <= w.seq < 8}


def _cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _cut_by(path, nbytes):
    seg = path / SEG
    os.truncate(seg, seg.stat().st_size - nbytes)


@pytest.fixture
def store(tmp_path):
    _store(tmp_path / "s")
    return tmp_path / "s"


def _cut_cases(path):
    off = _record_offsets(path)
    size = (path / SEG).stat().st_size
    last_len = off[7][1]
    return {"by 1": (1, [7]), "by 3": (3, [7]), "most of the last record": (last_len - 2, [7]),
            "in the middle": (size - off[5][0] - 5, [5, 6, 7]),
            # The bytes lost outnumber those left (the manifest check once refused such a
            # stretch, so that repair's own MANIFEST made every command fail), and a cut into
            # the segment header or to nothing (a size under the header's once failed that check).
            "at the second record": (size - off[5][0], [5, 6, 7]),
            "into the header": (size - 20, [4, 5, 6, 7]), "to nothing": (size, [4, 5, 6, 7])}


@pytest.mark.parametrize("case", ["by 1", "by 3", "most of the last record", "in the middle", "at the second record",
                                  "into the header", "to nothing"])
@pytest.mark.parametrize("header", [False, True])
def test_cut_sealed_segment_is_read_and_repaired(store, capsys, case, header):
    code, whole, _ = _cli(capsys, "cat", str(store))
    assert code == 0
    whole = whole.splitlines()
    nbytes, lost = _cut_cases(store)[case]
    if header:  # a flipped segment header byte too
        with open(store / SEG, "r+b") as f:
            f.seek(5)
            f.write(b"\xff")
    _cut_by(store, nbytes)
    lost_words = f"seq {lost[0]}" if len(lost) == 1 else f"seqs {lost[0]}..{lost[-1]}"

    # Readers open the store: cat refuses naming the segment and the seqs, --skip-damaged reads the rest.
    code, out, err = _cli(capsys, "cat", str(store))
    assert code != 0 and SEG in err and lost_words in err and out == ""
    assert "cclog fsck --repair --discard-damaged" in err
    code, out, err = _cli(capsys, "cat", str(store), "--skip-damaged")
    kept = out.splitlines()
    assert len(kept) == 3 * (10 - len(lost)) and set(kept) <= set(whole)
    assert lost_words in err

    # A writer refuses rather than append after (or delete) the cut segment.
    with pytest.raises(DamagedError, match="a writer cannot open the store"):
        cclogfs.open_store(store)

    # Repair keeps the records' bytes and names the seqs: exit 4, not 8. A damaged header, or
    # one the cut reached, is rebuilt from the name and the manifest (the damage stays named).
    before = (store / SEG).read_bytes()
    code, out, err = _cli(capsys, "fsck", str(store), "--repair")
    assert code == 4 and lost_words in out + err and "run `cclog fsck`" not in out + err
    after = (store / SEG).read_bytes()
    assert after[32:] == before[32:]
    assert (after == before) == (not header and len(before) >= 32), out

    code, out, err = _cli(capsys, "fsck", str(store), "--repair", "--discard-damaged")
    assert code == 1 and lost_words in out + err
    code, out, err = _cli(capsys, "fsck", str(store))
    assert code == 0, out + err
    code, out, _ = _cli(capsys, "cat", str(store))
    assert code == 0 and out.splitlines() == kept

    # Appends work again and take fresh seqs.
    with cclogfs.open_store(store) as s:
        s.put_window("/a", [(99000, json.dumps({"w": 99}))])
    with cclogfs.open_store(store, readonly=True) as s:
        got = [w.seq for w in s.query()]
    assert got == sorted(set(got)) and got[-1] == 10 and not set(lost) & set(got)


def test_failure_while_repair_commits_leaves_it_repairable(store, capsys, monkeypatch):
    _cut_by(store, 3)
    from cclogfs.store.store import Store

    def fail(self, manifest):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Store, "commit_manifest", fail)
    code, _, err = _cli(capsys, "fsck", str(store), "--repair", "--discard-damaged")
    assert code != 0
    monkeypatch.undo()
    code, out, err = _cli(capsys, "fsck", str(store), "--repair", "--discard-damaged")
    assert code == 1 and "seq 7" in out + err
    code, _, _ = _cli(capsys, "fsck", str(store))
    assert code == 0


def test_a_crash_while_a_header_cut_segment_gets_its_header_back_is_repaired_again(store, capsys, monkeypatch):
    """The manifest states the header's size before the file grows to it: a failure between
    the two leaves the segment cut short again, which the next repair names and drops."""
    _cut_by(store, (store / SEG).stat().st_size - 20)
    from cclogfs.store.fs import FileSystem

    def fail(self, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(FileSystem, "copy_range_atomic", fail)
    code, out, err = _cli(capsys, "fsck", str(store), "--repair")  # it rebuilds the header, the cut named
    assert code == 8, out + err
    monkeypatch.undo()
    assert _cli(capsys, "fsck", str(store), "--repair")[0] == 4
    code, out, err = _cli(capsys, "fsck", str(store), "--repair", "--discard-damaged")
    assert code == 1, out + err
    code, out, err = _cli(capsys, "fsck", str(store))
    assert code == 0, out + err
    with cclogfs.open_store(store) as s:
        s.put_window("/a", [(99000, json.dumps({"w": 99}))])
    code, out, _ = _cli(capsys, "cat", str(store))
    assert code == 0 and len(out.splitlines()) == 3 * 6 + 1


def test_active_segment_cut_at_a_record_boundary_below_the_checkpoint_is_damage(store, capsys):
    """Found by attack: the active segment cut at a record boundary below the last clean
    close's synced point ends cleanly, so no scan named what the cut took: fsck said clean,
    cat exited 0 without seq 9, and the writer gave seq 9 to its next record."""
    active = store / "00000000000000000008.seg"  # seqs 8 and 9, closed cleanly (checkpoint)
    with cclogfs.open_store(store, readonly=True) as s:
        offset = next(w._offset for w in s.query() if w.seq == 9)
    code, whole, _ = _cli(capsys, "cat", str(store))
    os.truncate(active, offset)
    code, out, err = _cli(capsys, "cat", str(store))
    assert code == 1 and out == "" and "00000000000000000008.seg" in err and "seq 9" in err, err
    code, out, err = _cli(capsys, "cat", str(store), "--skip-damaged")
    assert code == 3 and out.splitlines() == whole.splitlines()[:-3]
    assert _cli(capsys, "fsck", str(store))[0] == 1
    code, out, err = _cli(capsys, "fsck", str(store), "--repair")
    assert code == 4 and "seq 9" in out + err
    assert _cli(capsys, "fsck", str(store), "--repair", "--discard-damaged")[0] == 1
    code, out, err = _cli(capsys, "fsck", str(store))
    assert code == 0, out + err
    with cclogfs.open_store(store) as s:
        assert s.put_window("/a", [(99000, json.dumps({"w": 99}))]).seq == 10  # seq 9 is never given again
