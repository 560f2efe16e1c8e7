"""A read of a PART record in a sealed segment checks that its continuation follows (found by
an attack, issue 16: a PART flag forged with its CRC recomputed on the last record of a sealed
segment was named by fsck, but `cat`, which trusts a sealed segment's index, printed the
windows with exit 0 as if whole)."""

import json

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import CorruptionError
from cclogfs.store import encode
from cclogfs.store.format import RecordFlag
from helpers import SEG, patch_header

PART = int(RecordFlag.PART)


def _window(n=60, t0=0):
    return [(t0 + i, json.dumps({"i": i, "x": i / 7, "pad": "p" * (i % 40)})) for i in range(n)]


@pytest.fixture
def small_parts(monkeypatch):
    """Records of at most 950 bytes of window: a 60-message window is 5 parts."""
    monkeypatch.setattr(encode, "MAX_RECORD_RAW", 950)


def _offsets(path):
    with cclogfs.open_store(path, readonly=True) as store:
        return {w.seq: w.offset for w in store.query()}


def _cat(path, capsys):
    capsys.readouterr()
    code = main(["cat", str(path)])
    out, err = capsys.readouterr()
    return code, out, err


def _sealed_store(path, then, t=100):
    with cclogfs.open_store(path, create=True) as store:
        store.put_window("/a", [(0, "{}")], meta={"w": 0})
        store.put_window("/a", _window(t0=10), meta={"w": 1})  # seqs 1..5, split
        store.put_window(then, [(t, "{}")], meta={"w": 1})  # seq 6
        store.seal()
        store.put_window("/a", [(200, "{}")], meta={"w": 1})  # seq 7, in the next segment


def test_real_parts_in_a_sealed_segment_read_whole(tmp_path, small_parts, capsys):
    _sealed_store(tmp_path / "s", "/b")
    code, out, _ = _cat(tmp_path / "s", capsys)
    assert code == 0 and len(out.splitlines()) == 63


@pytest.mark.parametrize("seq, then, why", [
    (6, "/b", "it is the last record of the segment (seqs 0..6)"),
    (5, "/b", "a window of '/b', not '/a'"),
    (5, "/a", "it starts at 50 ns, before the part before ends (69 ns)"),
])  # fmt: skip
def test_a_forged_part_in_a_sealed_segment_is_refused_on_read(tmp_path, small_parts, capsys, seq, then, why):
    path = tmp_path / "s"
    _sealed_store(path, then, t=50 if then == "/a" else 100)  # the same stream: only its stamps tell
    patch_header(path / SEG, _offsets(path)[seq], flags=PART)
    code, out, err = _cat(path, capsys)
    assert code != 0 and "flagged PART" in err and why in err, (code, err)
    with cclogfs.open_store(path, readonly=True) as store, pytest.raises(CorruptionError, match="the window is incomplete"):
        for w in store.query():
            list(w.messages())
