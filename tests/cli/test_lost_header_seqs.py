"""An active segment whose header was lost after a clean close synced seqs 8..9 into it
(cut to 0 or 10 bytes): `fsck --repair` names those seqs lost, and they are never given to
new records. Found by the attack of l-atk5: repair removed the segment and the next put took
seq 8 again, so a consumer that had seen seq 8 saw another window under it. Repair now
seals the segment with its records in `discarded` (end_seq stays 10), as a sealed segment
cut to nothing ends after `--discard-damaged`."""

from __future__ import annotations

import json

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import DamagedError
from cclogfs.store import header_repair
from cclogfs.store.format import segment_name


def _store(path):
    with cclogfs.open_store(path, create=True, segment_records=4) as s:
        for w in range(10):
            s.put_window("/a", [(w * 1000 + i, json.dumps({"w": w, "i": i})) for i in range(3)])
    return path


def _cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _seqs(path, **query):
    with cclogfs.open_store(path, readonly=True) as s:
        return [w.seq for w in s.query(**query)]


@pytest.mark.parametrize("flags", [[], ["--discard-damaged"]])
@pytest.mark.parametrize("size", [0, 10])
def test_seqs_lost_with_an_active_header_are_never_reused(tmp_path, capsys, monkeypatch, flags, size):
    store = _store(tmp_path / "s")
    seg = store / segment_name(8)
    seg.write_bytes(seg.read_bytes()[:size])
    early = cclogfs.open_store(store, readonly=True)  # a reader open since before the repair
    with pytest.raises(DamagedError, match=r"seqs 8\.\.9"):
        list(early.query())

    # A reader that opens while repair rebuilds the lost header sees seqs 0..7 and the loss named.
    during = []
    rewrite = header_repair._rewrite

    def reader_opens_first(store_, seg_, header):
        with pytest.raises(DamagedError, match=r"seqs 8\.\.9"):
            _seqs(store)
        during.append(_seqs(store, skip_damaged=True))
        rewrite(store_, seg_, header)

    monkeypatch.setattr(header_repair, "_rewrite", reader_opens_first)
    code, out, err = _cli(capsys, "fsck", "--repair", store, *flags)
    monkeypatch.undo()
    assert code == 1, out + err
    assert "seqs 8..9" in out and "never reused" in out and "torn tail" not in out
    assert during == [list(range(8))]
    code, out, err = _cli(capsys, "fsck", store)
    assert code == 0, out + err

    with cclogfs.open_store(store) as s:
        assert s.put_window("/a", [(99000, json.dumps({"w": 99}))]).seq == 10
    assert _seqs(store) == [*range(8), 10]
    code, out, _ = _cli(capsys, "cat", store)
    assert code == 0
    got = [(m["stamp_ns"], m["msg"]) for m in map(json.loads, out.splitlines())]
    assert got == [(w * 1000 + i, {"w": w, "i": i}) for w in range(8) for i in range(3)] + [(99000, {"w": 99})]

    early.refresh()  # the early reader, and a reopen, see the same
    assert [w.seq for w in early.query()] == [*range(8), 10]
    early.close()
    code, out, err = _cli(capsys, "fsck", store)
    assert code == 0, out + err
    with cclogfs.open_store(store) as s:  # the writer again: the next seq follows on
        assert s.put_window("/a", [(99001, "{}")]).seq == 11
    assert _seqs(store) == [*range(8), 10, 11]


def test_a_repair_stopped_before_the_header_is_rebuilt_keeps_the_seqs(tmp_path, capsys, monkeypatch):
    """The seal (with the loss in `discarded`) is committed before the header is written:
    a failure between them leaves a sealed entry ending at seq 10, which the next repair
    finishes; no writer reuses seq 8 meanwhile."""
    store = _store(tmp_path / "s")
    (store / segment_name(8)).write_bytes(b"")

    def fail(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(header_repair, "_rewrite", fail)
    code, out, err = _cli(capsys, "fsck", "--repair", store)
    monkeypatch.undo()
    assert code == 8, out + err
    # Stopped once the manifest states the header's size: a writer refuses (it cannot reuse 8).
    with pytest.raises(DamagedError, match=r"seqs 8\.\.9"):
        cclogfs.open_store(store)
    code, out, err = _cli(capsys, "fsck", "--repair", store)
    assert code == 1 and "rebuilt the segment header of 00000000000000000008.seg" in out, out + err
    assert _cli(capsys, "fsck", store)[0] == 0
    with cclogfs.open_store(store) as s:
        assert s.put_window("/a", [(99000, "{}")]).seq == 10
    assert _seqs(store) == [*range(8), 10]
