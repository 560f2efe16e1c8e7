"""A read of a crashed store (no checkpoint) whose unsynced tail holds a bad record with intact
records after it: the reader drops the tail from the bad record on (the prefix guarantee), but
the intact records past it are no torn write: the writer's open keeps them in a side file and
`fsck --repair` puts them back, `fsck` calls it an error and `info` notes it. `cat` and
`export` printed the shorter answer with exit 0 and not a word (found by flipping bytes of a
store cut by kill -9 mid-record). Now they refuse it, naming the file and offset, and with
--skip-damaged print what is readable, say what they left out and exit 3."""

from __future__ import annotations

from cclogfs.cli import main
from helpers import SEG, drop_checkpoint, flip, make_store


def _crashed_with_a_bad_record(path) -> int:
    """Six windows on "/a", no checkpoint (as after a crash), record seq 3 flipped."""
    recs = make_store(path, n=6, sync_every_ms=None, sync_every_bytes=None)
    drop_checkpoint(path)
    seq, off, length = recs[3]
    flip(path / SEG, off + length - 5)
    return off


def test_cat_does_not_drop_intact_records_of_a_torn_tail_silently(tmp_path, capsys):
    off = _crashed_with_a_bad_record(tmp_path / "s")
    rc = main(["cat", str(tmp_path / "s")])
    out, err = capsys.readouterr()
    assert rc != 0, "cat gave fewer messages with exit 0 and said nothing"
    assert err.count("\n") == 1 and f"{SEG} at offset {off}" in err and "fsck --repair" in err, err
    assert main(["cat", str(tmp_path / "s"), "--skip-damaged"]) == 3
    out, err = capsys.readouterr()
    assert len(out.splitlines()) == 3 * 20  # the windows before the bad record
    assert "intact records among them" in err and f"offset {off}" in err, err


def test_export_does_not_drop_intact_records_of_a_torn_tail_silently(tmp_path, capsys):
    off = _crashed_with_a_bad_record(tmp_path / "s")
    rc = main(["export", str(tmp_path / "s"), "--mcap", str(tmp_path / "out.mcap")])
    err = capsys.readouterr().err
    assert rc != 0 and f"{SEG} at offset {off}" in err, err
    assert not (tmp_path / "out.mcap").exists()


def test_a_plain_torn_tail_is_still_read_without_a_word(tmp_path, capsys):
    # A crash that tore the last write: no intact record after it, nothing stored is left out.
    recs = make_store(tmp_path / "s", n=6, sync_every_ms=None, sync_every_bytes=None)
    drop_checkpoint(tmp_path / "s")
    seq, off, length = recs[5]
    flip(tmp_path / "s" / SEG, off + length - 5)
    assert main(["cat", str(tmp_path / "s")]) == 0
    assert capsys.readouterr().err == ""


def test_play_and_plot_refuse_it_too(tmp_path, capsys):
    off = _crashed_with_a_bad_record(tmp_path / "s")
    assert main(["play", str(tmp_path / "s"), "--rate", "1000"]) == 1
    out, err = capsys.readouterr()
    assert out == "" and f"{SEG} at offset {off}" in err, err
    assert main(["plot", str(tmp_path / "s"), "--out", str(tmp_path / "plots")]) == 1
    assert f"{SEG} at offset {off}" in capsys.readouterr().err


def test_info_counts_without_them_and_exits_3(tmp_path, capsys):
    # info's totals leave the cut records out; it noted the cut, but exited 0 as for a clean store
    off = _crashed_with_a_bad_record(tmp_path / "s")
    assert main(["info", str(tmp_path / "s")]) == 3
    out = capsys.readouterr().out
    assert f"{SEG} at offset {off}" in out and "intact records among them" in out
    assert main(["info", "--json", str(tmp_path / "s")]) == 3
    capsys.readouterr()
