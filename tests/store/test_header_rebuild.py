"""`fsck --repair` rebuilds a damaged segment header from what is trusted (FORMAT.md, "Repair").

Found by using the CLI: one byte flipped in a sealed segment's header was named by `cclog
fsck` field by field, but `cclog fsck --repair` said "clean, nothing to repair" (exit 0)
and left it, and in an active segment's header it said "damage left" (exit 4) with every
record intact behind it: no way back to a clean store that keeps them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import StoreLockedError
from cclogfs.store import check_store, repair_store
from cclogfs.store.format import SEGMENT_HEADER_SIZE, segment_name, unpack_segment_header

SEALED, ACTIVE = segment_name(4), segment_name(8)  # of a store of 10 windows, 4 a segment


def _store(path, codec="columnar"):
    with cclogfs.open_store(path, create=True, segment_records=4, codec=codec) as store:
        for w in range(10):
            store.put_window("/a", [(w * 1000 + i, json.dumps({"w": w, "i": i})) for i in range(3)])
    return path


def _windows(path):
    with cclogfs.open_store(path, readonly=True) as store:
        return [(w.seq, w.name, [tuple(m) for m in w.messages()]) for w in store.query()]


def _flip(file, offset, bits=0xFF):
    data = bytearray(file.read_bytes())
    data[offset] ^= bits
    file.write_bytes(bytes(data))


def _segment_files(path):
    return sorted(n for n in os.listdir(path) if n.endswith(".seg") or ".seg." in n)


def _expected_files(name):
    """One file per segment: repair seals a damaged active segment, and a new one follows it."""
    return [segment_name(0), segment_name(4), segment_name(8)] + ([segment_name(10)] if name == ACTIVE else [])


@pytest.mark.parametrize("name", [SEALED, ACTIVE])
@pytest.mark.parametrize("offset", range(SEGMENT_HEADER_SIZE))
def test_a_flipped_header_byte_is_rebuilt_and_every_record_kept(tmp_path, name, offset):
    path = _store(tmp_path / "s")
    before, records = _windows(path), (path / name).read_bytes()[SEGMENT_HEADER_SIZE:]
    _flip(path / name, offset)
    assert check_store(str(path)).errors  # named by fsck (tests/store/test_header_damage.py)
    report = repair_store(str(path))
    assert report.exit_code == 1 and not report.damage_left and not report.unproven, report
    assert any(f"rebuilt the segment header of {name}" in a for a in report.actions), report.actions
    after = check_store(str(path))
    assert not after.findings, after.findings
    assert after.records == 10
    data = (path / name).read_bytes()
    assert unpack_segment_header(data)[0] == int(name[:20]) and data[SEGMENT_HEADER_SIZE:] == records
    assert _windows(path) == before
    assert _segment_files(path) == _expected_files(name)
    assert repair_store(str(path)).exit_code == 0  # nothing left to do


def test_the_cli_rebuilds_a_sealed_header_and_cat_gives_every_record_back(tmp_path, capsys):
    path = _store(tmp_path / "s")
    assert main(["cat", str(path)]) == 0
    before = capsys.readouterr().out
    _flip(path / SEALED, 17, 0x10)  # created_ns: only the CRC says it changed
    assert main(["fsck", "--repair", str(path)]) == 1
    out = capsys.readouterr().out
    assert (f"repaired: rebuilt the segment header of {SEALED} (its CRC (bytes 28-31) does not match bytes "
            "0-27: created_ns (16-23), manifest_gen (24-27) or the CRC changed): first_seq 4, as its name, the "
            "manifest and its first record state; its 4 records kept byte for byte") in out  # fmt: skip
    assert "repaired, now clean" in out
    assert main(["fsck", str(path)]) == 0
    capsys.readouterr()
    assert main(["cat", str(path)]) == 0
    assert capsys.readouterr().out == before


def _records_disagree(tmp_path):
    """Segment 4's file holds segment 0's records (same size: codec none, same-length texts),
    its header damaged: the name and the manifest say seq 4, the records say 0."""
    path = _store(tmp_path / "s", codec="none")
    data = bytearray((path / segment_name(0)).read_bytes())
    assert len(data) == (path / SEALED).stat().st_size
    data[10] ^= 4
    (path / SEALED).write_bytes(bytes(data))
    return path, bytes(data)


def test_records_that_disagree_with_the_name_are_not_guessed_at(tmp_path, capsys):
    path, data = _records_disagree(tmp_path)
    assert main(["fsck", "--repair", str(path)]) == 4
    out = capsys.readouterr().out
    assert (f"not repaired: {SEALED}: segment header kept as it is, not rebuilt (first_seq (bytes 8-15) is "
            "262144, the file name says 4; its CRC (bytes 28-31) does not match bytes 0-27): its first record "
            "states seq 0, but its name and the manifest say 4: which is right cannot be told, so nothing is "
            "guessed") in out  # fmt: skip
    assert "cannot prove how to mend" in out and "now clean" not in out
    assert (path / SEALED).read_bytes() == data  # the bytes kept
    assert check_store(str(path)).errors
    assert repair_store(str(path)).exit_code == 4  # and again: still refused, still kept
    assert (path / SEALED).read_bytes() == data


def test_discard_damaged_drops_the_records_that_disagree_naming_their_seqs(tmp_path, capsys):
    path, data = _records_disagree(tmp_path)
    assert main(["fsck", "--repair", "--discard-damaged", str(path)]) == 1
    out = capsys.readouterr().out
    assert f"discarded {SEALED} at offset 32, 764 bytes, seqs 4..7: sequence gap" in out
    assert (f"rebuilt the segment header of {SEALED} (first_seq (bytes 8-15) is 262144, the file name says 4; "
            "its CRC (bytes 28-31) does not match bytes 0-27): first_seq 4, as its name and the manifest state "
            "(the records that did not agree were discarded: seqs 4..7)") in out  # fmt: skip
    assert not check_store(str(path)).findings
    assert [seq for seq, _n, _m in _windows(path)] == [0, 1, 2, 3, 8, 9]
    assert (path / SEALED).read_bytes()[SEGMENT_HEADER_SIZE:] == data[SEGMENT_HEADER_SIZE:]


@pytest.mark.parametrize("name", [SEALED, ACTIVE])
@pytest.mark.parametrize("record", ["first", "last"])
def test_a_header_with_a_damaged_record_behind_it_is_rebuilt_and_the_damage_stays_named(tmp_path, name, record):
    """Found by attack: with its first record damaged too, a header was rebuilt only by
    `--discard-damaged` (and with any other record damaged, too): plain `--repair` kept it
    damaged although the name and the manifest state its first_seq and every intact record
    agrees. Now the header is rebuilt and the damaged record stays named (exit 4) until
    `--discard-damaged`, as damage elsewhere does."""
    path = _store(tmp_path / "s")
    seg = path / name
    _flip(seg, 3)
    _flip(seg, SEGMENT_HEADER_SIZE + 2 if record == "first" else seg.stat().st_size - 5)
    lost = int(name[:20]) + (0 if record == "first" else 3 if name == SEALED else 1)
    records = seg.read_bytes()[SEGMENT_HEADER_SIZE:]
    report = repair_store(str(path))
    assert report.exit_code == 4 and not report.unproven, report
    proof = "its name and the manifest state (its first record is damaged)" if record == "first" else \
        "its name, the manifest and its first record state"
    assert any(f"rebuilt the segment header of {name}" in a and proof in a and
               f"the damaged ones still named as damage (seq {lost}:" in a for a in report.actions), report.actions
    assert len(report.damage_left) == 1 and f", seq {lost}: " in report.damage_left[0], report.damage_left
    if record == "first":
        assert report.damage_left[0].startswith(f"{name} at offset {SEGMENT_HEADER_SIZE}, ")
    assert seg.read_bytes()[SEGMENT_HEADER_SIZE:] == records  # every byte behind the header kept
    assert unpack_segment_header(seg.read_bytes())[0] == int(name[:20])
    check = check_store(str(path))
    assert len(check.errors) == 1 and f"seq {lost}" in str(check.errors[0]), check.findings
    assert repair_store(str(path)).exit_code == 4  # the damage is left for --discard-damaged
    report = repair_store(str(path), discard_damaged=True)
    assert report.exit_code == 1 and not report.unproven, report
    assert not check_store(str(path)).findings
    assert [seq for seq, _n, _m in _windows(path)] == [s for s in range(10) if s != lost]


# -- a crash in the middle of the rewrite ------------------------------------------------

_KILLED_REPAIR = """
import os, signal, sys
from cclogfs.store import repair_store
from cclogfs.store.fs import FileSystem

class Killed(FileSystem):
    def rename(self, src, dst):
        if src.endswith(".seg.tmp") and sys.argv[2] == "before":
            os.kill(os.getpid(), signal.SIGKILL)  # the new file written and synced, not renamed
        super().rename(src, dst)
        if src.endswith(".seg.tmp"):
            os.kill(os.getpid(), signal.SIGKILL)  # renamed, the manifest not told yet

repair_store(sys.argv[1], fs=Killed())
"""


@pytest.mark.parametrize("name", [SEALED, ACTIVE])
@pytest.mark.parametrize("when", ["before", "after"])
def test_a_repair_killed_around_the_rename_leaves_a_repairable_store(tmp_path, name, when):
    path = _store(tmp_path / "s")
    before, records = _windows(path), (path / name).read_bytes()[SEGMENT_HEADER_SIZE:]
    _flip(path / name, 9)
    done = subprocess.run([sys.executable, "-c", _KILLED_REPAIR, str(path), when], capture_output=True, text=True)
    assert done.returncode == -9, done.stderr  # killed at the rename, not finished or failed
    leftovers = [n for n in os.listdir(path) if n.endswith(".tmp")]
    assert leftovers == ([f"{name}.tmp"] if when == "before" else [])
    # It opens: the header still damaged, or (renamed) an active one's manifest entry left.
    pending = check_store(str(path)).errors
    assert bool(pending) == (when == "before" or name == ACTIVE), pending
    report = repair_store(str(path))
    assert report.exit_code == (1 if pending else 0) and not report.damage_left and not report.unproven, report
    if when == "after" and name == ACTIVE:
        assert any("intact (rebuilt by an earlier repair)" in a for a in report.actions), report.actions
    assert not check_store(str(path)).findings
    assert _windows(path) == before  # no record lost, none twice
    assert (path / name).read_bytes()[SEGMENT_HEADER_SIZE:] == records
    assert _segment_files(path) == _expected_files(name)


def test_a_failed_rename_changes_nothing_and_repair_runs_again(tmp_path, monkeypatch):
    path = _store(tmp_path / "s")
    before = _windows(path)
    _flip(path / SEALED, 20)
    data = (path / SEALED).read_bytes()
    real = cclogfs.store.fs.FileSystem.rename

    def rename(self, src, dst):
        if src.endswith(".seg.tmp"):
            raise OSError(5, "Input/output error (injected)")
        real(self, src, dst)

    monkeypatch.setattr(cclogfs.store.fs.FileSystem, "rename", rename)
    with pytest.raises(OSError):
        repair_store(str(path))
    assert (path / SEALED).read_bytes() == data
    assert not [n for n in os.listdir(path) if n.endswith(".tmp")]  # its space given back at once
    monkeypatch.undo()
    assert repair_store(str(path)).exit_code == 1
    assert not check_store(str(path)).findings and _windows(path) == before
    assert not [n for n in os.listdir(path) if n.endswith(".tmp")]


# -- two processes -----------------------------------------------------------------------

_WRITER = """
import sys, cclogfs
store = cclogfs.open_store(sys.argv[1])
print("open", flush=True)
sys.stdin.read()  # holds the lock until the test closes stdin
store.close()
"""


def test_repair_refuses_while_a_writer_holds_the_store(tmp_path, capsys):
    path = _store(tmp_path / "s")
    _flip(path / SEALED, 12)
    data = (path / SEALED).read_bytes()
    writer = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert writer.stdout.readline() == "open\n"
        with pytest.raises(StoreLockedError, match="locked by another writer"):
            repair_store(str(path))
        assert main(["fsck", "--repair", str(path)]) == 8
        err = capsys.readouterr().err
        assert "locked by another writer" in err and "readonly=True" not in err, err  # the CLI's words
        assert (path / SEALED).read_bytes() == data
        assert not [n for n in os.listdir(path) if n.endswith(".tmp")]
    finally:
        writer.stdin.close()
        assert writer.wait(timeout=60) == 0
    assert repair_store(str(path)).exit_code == 1  # the writer gone, the header is rebuilt
    assert not check_store(str(path)).findings


def test_a_compacted_generation_is_rebuilt_under_its_own_name(tmp_path):
    from cclogfs.store import Replacement

    path = _store(tmp_path / "s")
    with cclogfs.open_store(path) as store:  # seq 5 replaced: segment 4 becomes generation 1
        store.rewrite(lambda w: Replacement([(w.start_ns, '{"r":1}')], {}) if w.seq == 5 else None)
    name = segment_name(4, 1)
    before, records = _windows(path), (path / name).read_bytes()[SEGMENT_HEADER_SIZE:]
    _flip(path / name, 8)
    report = repair_store(str(path))
    assert report.exit_code == 1 and any(f"rebuilt the segment header of {name}" in a for a in report.actions)
    assert not check_store(str(path)).findings
    assert _windows(path) == before and (path / name).read_bytes()[SEGMENT_HEADER_SIZE:] == records
    assert _segment_files(path) == [segment_name(0), name, segment_name(8)]


def test_repair_does_not_rebuild_a_damaged_manifest_under_a_running_writer(tmp_path, capsys):
    # The manifest rebuild ran before repair took the lock: a writer that still held the
    # store would then commit its own manifest over the rebuilt one.
    path = _store(tmp_path / "s")
    writer = subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert writer.stdout.readline() == "open\n"
        _flip(path / "MANIFEST", 20, 0x01)  # bit rot under the running writer
        manifest = (path / "MANIFEST").read_bytes()
        assert main(["fsck", "--repair", str(path)]) == 8
        assert "locked by another writer" in capsys.readouterr().err
        assert (path / "MANIFEST").read_bytes() == manifest and not (path / "quarantine").exists()
    finally:
        writer.stdin.close()
        writer.wait(timeout=60)


def test_repair_of_a_directory_that_holds_no_store_names_the_command_not_the_api(tmp_path, capsys):
    # Found by attack: 'cannot repair DIR: ... pass create=True to make one' (the Python API's
    # words; `cli_words` was applied to every other command's store errors).
    assert main(["fsck", "--repair", str(tmp_path)]) == 8
    err = capsys.readouterr().err
    assert "create=True" not in err and "`cclog record SOURCE --store PATH` makes one" in err, err
