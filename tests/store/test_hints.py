"""Every repair a store-side error names is one that works: each test damages a store as a
user might find it, runs the command that refuses, takes the `cclog ...` command the error
names, runs it as the user would, and checks that the refused command then works (found by
attack: a reader refused an active segment whose header was lost with `--repair
--discard-damaged` where plain `--repair` suffices; a sealed segment that grew sent the user
to `cclog fsck`, whose `--repair` refused it with the same words, exit 8)."""

from __future__ import annotations

import json
import os
import re
import shlex

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import CclogError
from cclogfs.store.format import segment_name

SEALED, ACTIVE = segment_name(4), segment_name(8)  # of a store of 10 windows, 4 a segment


def _store(path):
    with cclogfs.open_store(path, create=True, segment_records=4) as store:
        for w in range(10):
            store.put_window("/a", [(w * 1000 + i, json.dumps({"w": w, "i": i})) for i in range(3)])
    return path


def _flip(file, offset):
    data = bytearray(file.read_bytes())
    data[offset] ^= 0xFF
    file.write_bytes(bytes(data))


def _named(text):
    """The first `cclog ...` command an error names, as argv for `main` (the store appended)."""
    m = re.search(r"`cclog ([^`]+)`", text)
    assert m is not None, text
    return shlex.split(m.group(1))


def _cat(path, capsys):
    capsys.readouterr()
    code = main(["cat", str(path)])
    out, err = capsys.readouterr()
    return code, len(out.splitlines()), err


def _follow(path, hint, capsys):
    code = main([*_named(hint), str(path)])
    capsys.readouterr()
    return code


@pytest.mark.parametrize("damage, left", [("flip", 30), ("cut", 24)])
def test_a_readers_refusal_of_a_lost_active_header_names_plain_repair_and_it_works(tmp_path, capsys, damage, left):
    path = _store(tmp_path / "s")
    seg = path / ACTIVE
    if damage == "flip":
        _flip(seg, 5)  # no record lost
    else:
        os.truncate(seg, 10)  # the records the clean close synced are lost with it
    code, _n, err = _cat(path, capsys)
    assert code == 1 and "bad segment header" in err
    assert _named(err) == ["fsck", "--repair"], err  # was `--repair --discard-damaged`
    assert _follow(path, err, capsys) == 1
    assert _cat(path, capsys)[:2] == (0, left)
    assert main(["fsck", str(path)]) == 0


def test_a_writers_refusal_of_a_cut_sealed_segment_names_plain_repair_and_it_works(tmp_path, capsys):
    path = _store(tmp_path / "s")
    os.truncate(path / SEALED, (path / SEALED).stat().st_size - 3)
    with pytest.raises(CclogError) as refused:
        cclogfs.open_store(path)
    assert _named(str(refused.value)) == ["fsck", "--repair"], refused.value
    assert _follow(path, str(refused.value), capsys) == 4  # the cut named: damage left
    cclogfs.open_store(path).close()  # the writer opens now
    code, _n, err = _cat(path, capsys)  # reads refuse until the damage is dropped, and say how
    assert code == 1 and _named(err) == ["fsck", "--repair", "--discard-damaged"], err
    assert _follow(path, err, capsys) == 1
    assert _cat(path, capsys)[:2] == (0, 27)
    assert main(["fsck", str(path)]) == 0


def test_a_sealed_segment_that_grew_is_repaired_as_the_error_says(tmp_path, capsys):
    path = _store(tmp_path / "s")
    with open(path / SEALED, "ab") as f:
        f.write(b"added since")
    code, _n, err = _cat(path, capsys)
    assert code == 1 and "`cclog fsck --repair`" in err, err
    capsys.readouterr()
    assert main(["fsck", str(path)]) == 1  # it said "torn record in a sealed segment", no way on
    out = capsys.readouterr().out
    assert (f"{SEALED}: is {(path / SEALED).stat().st_size} bytes, it was sealed at "
            f"{(path / SEALED).stat().st_size - 11}: 11 bytes were added since; `cclog fsck --repair` moves them "
            "to quarantine/ and cuts the file back") in out and "1 errors, 0 warnings" in out, out
    assert main(["fsck", "--repair", str(path)]) == 4  # was 8: "cannot repair ... (run `cclog fsck`)"
    out = capsys.readouterr().out
    name = f"{SEALED}.tail-{(path / SEALED).stat().st_size}"
    assert f"had grown by 11 bytes since it was sealed" in out and f"quarantine/{name}" in out, out
    assert (path / "quarantine" / name).read_bytes() == b"added since"  # kept, not destroyed
    assert _cat(path, capsys)[:2] == (0, 30)  # every record back; the added bytes were never one
    capsys.readouterr()
    assert main(["fsck", str(path)]) == 1
    out = capsys.readouterr().out
    assert "`cclog fsck --repair --discard-damaged`" in out
    assert _follow(path, out, capsys) == 1
    assert main(["fsck", str(path)]) == 0


def test_a_damaged_manifest_names_the_repair_that_rebuilds_it(tmp_path, capsys):
    path = _store(tmp_path / "s")
    _flip(path / "MANIFEST", 40)
    code, _n, err = _cat(path, capsys)
    assert code == 1 and _named(err) == ["fsck", "--repair"], err
    assert _follow(path, err, capsys) == 4  # the damaged MANIFEST kept in quarantine
    assert _cat(path, capsys)[:2] == (0, 30)


def test_a_lost_manifest_names_the_repair_that_rebuilds_it(tmp_path, capsys):
    """It said "not a cclogfs store, or one whose manifest was lost (run `cclog fsck`)";
    `cclog fsck` said the same, and `fsck --repair` refused the store (exit 8)."""
    path = _store(tmp_path / "s")
    (path / "MANIFEST").unlink()
    code, _n, err = _cat(path, capsys)
    assert code == 1 and _named(err) == ["fsck", "--repair"], err
    capsys.readouterr()
    assert main(["fsck", "--repair", str(path)]) == 1
    assert "rebuilt MANIFEST from 3 segment files (new store id; retention's totals start again; it was missing)" \
        in capsys.readouterr().out
    assert _cat(path, capsys)[:2] == (0, 30)
    assert main(["fsck", str(path)]) == 0
    junk = tmp_path / "junk"
    junk.mkdir()
    (junk / "notes.txt").write_text("hi")
    assert main(["fsck", "--repair", str(junk)]) == 8  # no segment file: no store to rebuild
    assert "not a cclogfs store" in capsys.readouterr().err
    assert sorted(os.listdir(junk)) == ["notes.txt"]


@pytest.mark.parametrize("which, repair, left", [(ACTIVE, ["fsck", "--repair"], 24),
                                                 (SEALED, ["fsck", "--repair", "--discard-damaged"], 18)])
def test_a_missing_segment_names_the_repair_that_names_its_seqs_lost(tmp_path, capsys, which, repair, left):
    """It said only "... is missing", and `fsck --repair` refused the store (exit 8) with
    the same words: no way back. Now the error names the seqs and the repair, which puts an
    empty file in its place so that they are named lost, never reused; a sealed one only
    with --discard-damaged (a restored file could no longer take its place)."""
    path = _store(tmp_path / "s")
    (path / which).unlink()
    code, _n, err = _cat(path, capsys)
    assert code == 1 and _named(err) == repair, err
    assert "seqs 8..9" in err if which == ACTIVE else "(seqs 4..7)" in err
    if which == SEALED:
        assert main(["fsck", "--repair", str(path)]) == 8  # refused: the user must say the records are gone
        assert not (path / which).exists()
    assert _follow(path, err, capsys) == 1
    assert _cat(path, capsys)[:2] == (0, left)
    assert main(["fsck", str(path)]) == 0
    with cclogfs.open_store(path) as store:  # the lost seqs are never given to new records
        assert store.put_window("/a", [(99_999, "{}")]).seq == 10


@pytest.mark.parametrize("which", [SEALED, ACTIVE])
def test_a_damaged_record_a_read_meets_names_the_repair(tmp_path, capsys, which):
    """A read that met a damaged record nobody had named yet said only "record at offset N
    is damaged: payload checksum mismatch"."""
    path = _store(tmp_path / "s")
    _flip(path / which, (path / which).stat().st_size - 5)
    code, _n, err = _cat(path, capsys)
    assert code == 1 and _named(err) == ["fsck", "--repair"], err
    assert _follow(path, err, capsys) == 4  # named: damage left
    code, _n, err = _cat(path, capsys)
    assert code == 1 and _named(err) == ["fsck", "--repair", "--discard-damaged"], err
    assert _follow(path, err, capsys) == 1
    assert _cat(path, capsys)[:2] == (0, 27)
