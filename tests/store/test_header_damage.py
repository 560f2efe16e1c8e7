"""A damaged segment header is named in plain terms: which field, at which offset, and
what the manifest says the segment held (found by an attack, issue 16: one flipped bit was
reported as "damaged or names another first sequence number", and `fsck --repair` said the
segment lost "seqs 0..-1")."""

from __future__ import annotations

import json

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.store.format import pack_segment_header, segment_header_fault, segment_name


def _store(path, n=10):
    with cclogfs.open_store(path, create=True, segment_records=4) as store:
        for w in range(n):
            store.put_window("/a", [(w * 1000 + i, json.dumps({"w": w, "i": i})) for i in range(3)])
    return path


def _flip(path, offset, bit=4):
    data = bytearray(path.read_bytes())
    data[offset] ^= bit
    path.write_bytes(bytes(data))


@pytest.mark.parametrize(
    "offset, says",
    [
        (1, "magic (bytes 0-3) is b'CGLS', not b'CCLS'; its CRC"),
        (4, "version (bytes 4-5) is 5, not 1; its CRC"),
        (6, "flags (bytes 6-7) is 4, not 0; its CRC"),
        (8, "first_seq (bytes 8-15) is 4, the file name says 0; its CRC"),
        (17, "its CRC (bytes 28-31) does not match bytes 0-27: created_ns (16-23), manifest_gen (24-27) or the CRC"),
        (29, "its CRC (bytes 28-31) does not match bytes 0-27: created_ns (16-23)"),
    ],
)
def test_the_fault_names_the_field(offset, says):
    header = bytearray(pack_segment_header(0, 123, 2))
    assert segment_header_fault(bytes(header), 0) == ""
    header[offset] ^= 4
    assert segment_header_fault(bytes(header), 0).startswith(says)
    assert "cut short to 10 bytes" in segment_header_fault(bytes(header[:10]), 0)


def test_fsck_names_a_sealed_segments_header_and_still_checks_its_records(tmp_path, capsys):
    store = _store(tmp_path / "s")
    _flip(store / segment_name(4), 10)  # first_seq's third byte
    assert main(["fsck", str(store)]) == 1
    out = capsys.readouterr().out
    assert (f"{segment_name(4)}: segment header (offset 0, 32 bytes) is damaged: first_seq (bytes 8-15) is "
            f"{4 + (4 << 16)}, the file name says 4; its CRC (bytes 28-31) does not match bytes 0-27; the manifest "
            "says the segment holds seqs 4..7, 4000..7002 ns") in out  # fmt: skip
    assert "10 records, 30 messages, 1 errors" in out  # its 4 records read intact too


def test_a_tail_header_loses_no_record_and_says_so(tmp_path, capsys):
    store = _store(tmp_path / "s", n=3)  # one segment, not sealed
    _flip(store / segment_name(0), 10)
    assert main(["fsck", "--repair", str(store)]) == 1  # was 4: damage left, though nothing was lost
    out = capsys.readouterr().out
    assert "seqs 0..-1" not in out and "no seq:" not in out
    assert ("bad segment header (first_seq (bytes 8-15) is 262144, the file name says 0; its CRC (bytes 28-31) "
            "does not match bytes 0-27): 32 bytes below the synced point damaged (no record lost)") in out  # fmt: skip
    assert "rebuilt the segment header of 00000000000000000000.seg" in out  # tests/store/test_header_rebuild.py
    assert main(["cat", str(store)]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 9  # every record behind the header


@pytest.mark.parametrize("size", [0, 10])
def test_an_active_header_cut_short_after_a_clean_close_loses_records_loudly(tmp_path, capsys, size):
    # Found by an attack: the clean close synced seqs 8..9 into the active segment; cutting
    # its file inside the header made fsck say 'clean' and cat print 24 of 30 messages, exit 0.
    store = _store(tmp_path / "s")
    seg = store / segment_name(8)
    seg.write_bytes(seg.read_bytes()[:size])
    assert main(["fsck", str(store)]) == 1
    out = capsys.readouterr().out
    assert "seqs 8..9: bad segment header" in out
    assert "torn tail" not in out  # not also called unsynced writes the writer may cut
    assert main(["cat", str(store)]) != 0
    capsys.readouterr()
    assert main(["fsck", "--repair", str(store)]) == 1
    out = capsys.readouterr().out
    assert "sealed, its records lost" in out and "damaged (seqs 8..9)" in out and "torn tail" not in out
    assert main(["cat", str(store)]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 24


@pytest.mark.parametrize("size", [0, 10])
def test_a_writer_refuses_a_store_whose_active_header_lost_synced_records(tmp_path, capsys, size):
    # Found after the fix above: `record --append` (any writer) took the cut segment for a
    # torn tail, deleted it and appended, exit 0: seqs 8..9 gone without a word.
    store = _store(tmp_path / "s")
    seg = store / segment_name(8)
    seg.write_bytes(seg.read_bytes()[:size])
    with pytest.raises(cclogfs.errors.DamagedError, match=r"seqs 8\.\.9.*fsck --repair"):
        cclogfs.open_store(store)
    assert seg.read_bytes() == seg.read_bytes()[:size] and seg.exists()  # nothing deleted
    source = tmp_path / "one.jsonl"
    source.write_text('{"topic": "/b", "stamp_ns": 99999, "msg": {"k": 1}}\n')
    assert main(["record", str(source), "--store", str(store), "--append"]) == 1
    assert "a writer cannot open the store" in capsys.readouterr().err
    assert seg.exists()
    assert main(["fsck", "--repair", str(store)]) == 1  # repair drops it, naming the seqs
    assert "damaged (seqs 8..9)" in capsys.readouterr().out
    assert main(["record", str(source), "--store", str(store), "--append"]) == 0
