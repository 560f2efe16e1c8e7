"""One test per corruption rule: what survives, and the reason reported."""

import json
import struct

import pytest

import cclogfs
from cclogfs.errors import CorruptionError, UnknownCodecError
from cclogfs.store.format import RECORD_FIXED, RECORD_FIXED_SIZE, crc32c

SEG = "00000000000000000000.seg"


def make_store(path, n=4, **opts):
    with cclogfs.open_store(path, create=True, **opts) as store:
        for i in range(n):
            store.put_window("/a", [(i * 10 + k, json.dumps({"i": i, "k": k})) for k in range(20)])
        return [(w.seq, w._offset, w._length) for w in store.query()]


def seqs(store):
    return [w.seq for w in store.query()]


def patch_header(path, offset, **fields):
    """Rewrite fixed-header fields of the record at `offset`, then fix its header CRC."""
    data = bytearray(path.read_bytes())
    names = ["magic", "kind", "version", "flags", "header_len", "seq", "start", "end", "count",
             "codec", "name_len", "config_len", "meta_len", "raw_len", "enc_len", "xxh3"]  # fmt: skip
    values = dict(zip(names, RECORD_FIXED.unpack_from(data, offset)))
    values.update(fields)
    RECORD_FIXED.pack_into(data, offset, *values.values())
    header_len = values["header_len"]
    struct.pack_into("<I", data, offset + header_len - 4, crc32c(bytes(data[offset : offset + header_len - 4])))
    path.write_bytes(bytes(data))


def flip(path, offset):
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x40
    path.write_bytes(bytes(data))


def test_torn_tail_is_truncated_and_reported(tmp_path):
    recs = make_store(tmp_path / "s")
    seg = tmp_path / "s" / SEG
    cut = recs[3][1] + recs[3][2] // 2
    with open(seg, "r+b") as f:
        f.truncate(cut)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1, 2]
        (p,) = store.recovery.problems
        assert (p.reason, p.offset, p.dropped_bytes) == ("torn record", recs[3][1], cut - recs[3][1])
    assert seg.stat().st_size == recs[3][1]


@pytest.mark.parametrize("where, reason", [("payload", "payload checksum mismatch"),
                                           ("header", "header checksum mismatch")])  # fmt: skip
def test_checksum_mismatch_ends_the_tail(tmp_path, where, reason):
    recs = make_store(tmp_path / "s")
    seq, off, length = recs[1]
    flip(tmp_path / "s" / SEG, off + (length - 5 if where == "payload" else RECORD_FIXED_SIZE + 1))
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0]  # nothing after the damage: no hole
        (p,) = store.recovery.problems
        assert (p.reason, p.offset) == (reason, off)


def test_bad_length_is_caught_before_allocating(tmp_path):
    recs = make_store(tmp_path / "s")
    patch_header(tmp_path / "s" / SEG, recs[2][1], enc_len=1 << 40)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1]
        assert store.recovery.problems[0].reason == "bad record length"


def test_zero_fill(tmp_path):
    recs = make_store(tmp_path / "s")
    with open(tmp_path / "s" / SEG, "ab") as f:
        f.write(b"\0" * 4096)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1, 2, 3]
        assert store.recovery.problems[0].reason == "zero fill"
        assert store.recovery.problems[0].dropped_bytes == 4096


def test_unknown_record_kind_is_skipped_not_the_end(tmp_path):
    recs = make_store(tmp_path / "s")
    patch_header(tmp_path / "s" / SEG, recs[1][1], kind=9)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 2, 3]
        assert store.recovery.problems == []
        (p,) = store.recovery.skipped
        assert (p.reason, p.offset) == ("unknown record kind", recs[1][1])
        assert store.put_window("/a", [(999, "1")]).seq == 4


def test_unknown_codec_is_kept_and_named_on_read(tmp_path):
    recs = make_store(tmp_path / "s")
    patch_header(tmp_path / "s" / SEG, recs[1][1], codec=77)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1, 2, 3] and store.recovery.clean
        bad = [w for w in store.query() if w.seq == 1][0]
        with pytest.raises(CorruptionError, match="names codec 77"):
            list(bad.messages())
        assert len(list([w for w in store.query() if w.seq == 2][0].messages())) == 20


def test_unknown_codec_id_in_config(tmp_path):
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, codec="zstd") as store:
        store.put_window("/a", [(0, "1")])
        (w,) = store.query()
        offset = w._offset
    data = bytearray((path / SEG).read_bytes())
    i = data.index(b'"zstd"', offset)
    data[i : i + 6] = b'"zst0"'
    (path / SEG).write_bytes(bytes(data))
    patch_header(path / SEG, offset)  # re-seal the header CRC over the edited config
    with cclogfs.open_store(path) as store:
        (w,) = store.query()
        with pytest.raises(UnknownCodecError, match="unknown codec 'zst0'"):
            list(w.messages())


def test_damage_in_a_sealed_segment_is_an_error_on_read(tmp_path):
    recs = make_store(tmp_path / "s", n=30, segment_bytes=4096, sync_every_bytes=1)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        seg = store.sealed[0]
        first = [w for w in store.query() if w.seq == seg.first_seq + 1][0]
        path, off = seg.path, first._offset
    flip(tmp_path / "s" / path.rsplit("/", 1)[1], off + first._length - 3)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert store.recovery.clean  # sealed segments are trusted on open (no scan)
        windows = list(store.query())
        assert len(windows) == 30  # still listed
        damaged = [w for w in windows if w.seq == first.seq][0]
        with pytest.raises(CorruptionError, match=f"offset {off} is damaged: payload checksum") as err:
            list(damaged.messages())
        assert err.value.reason == "payload checksum mismatch" and err.value.offset == off
        assert sum(len(list(w.messages())) for w in windows if w.seq != first.seq) == 29 * 20


def test_index_rebuilt_when_missing_or_damaged(tmp_path):
    make_store(tmp_path / "s", n=80, segment_bytes=4096, sync_every_bytes=1)
    idx = sorted((tmp_path / "s").glob("*.idx"))
    assert len(idx) >= 2
    idx[0].unlink()
    flip(idx[1], 40)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == list(range(80))
    assert idx[0].exists()  # the writer wrote it again


def test_damaged_manifest_is_named(tmp_path):
    make_store(tmp_path / "s")
    flip(tmp_path / "s" / "MANIFEST", 12)
    with pytest.raises(CorruptionError, match="MANIFEST is damaged: header checksum mismatch"):
        cclogfs.open_store(tmp_path / "s")


def test_missing_sealed_segment_is_named(tmp_path):
    make_store(tmp_path / "s", n=30, segment_bytes=4096, sync_every_bytes=1)
    (tmp_path / "s" / SEG).unlink()
    with pytest.raises(CorruptionError, match=f"lists segment {SEG}, which is missing"):
        cclogfs.open_store(tmp_path / "s")


def test_reader_does_not_repair(tmp_path):
    recs = make_store(tmp_path / "s")
    seg = tmp_path / "s" / SEG
    with open(seg, "r+b") as f:
        f.truncate(recs[3][1] + 10)
    before = seg.read_bytes()
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert seqs(store) == [0, 1, 2]
        assert store.recovery.problems[0].reason == "torn record"
    assert seg.read_bytes() == before


def test_sealed_segment_cut_at_a_record_boundary_is_not_a_silent_hole(tmp_path):
    # Cut exactly between records: every remaining record is intact, but some are missing.
    make_store(tmp_path / "s", n=80, segment_bytes=4096, sync_every_bytes=1)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        first = store.sealed[0]
        cut = [w for w in store.query() if w.seq == first.next_seq - 2][0]._offset
        expected_seqs = [w.seq for w in store.query()]
    with open(tmp_path / "s" / SEG, "r+b") as f:
        f.truncate(cut)
    for opts in ({"readonly": True}, {}):
        with cclogfs.open_store(tmp_path / "s", **opts) as store:
            with pytest.raises(CorruptionError, match="manifest says it was sealed at"):
                list(store.query())
            # Windows of put i span [10 i, 10 i + 19]: from here on only later segments answer.
            t = (store.sealed[1].first_seq + 1) * 10
            later = [w.seq for w in store.query(start_ns=t)]
            assert later == [s for s in expected_seqs if s >= store.sealed[1].first_seq]
            assert later


def test_record_of_a_newer_version_with_a_longer_header_is_skipped(tmp_path):
    # Version 2 appends 8 bytes to the header (allowed by the extension rules): a version 1
    # reader frames it by header_len, skips it, and keeps every later record.
    from cclogfs.store.format import RECORD_FIXED, crc32c, pack_record, xxh3

    recs = make_store(tmp_path / "s", n=3)
    seg = tmp_path / "s" / SEG
    data = seg.read_bytes()
    seq1 = data[recs[1][1] : recs[1][1] + recs[1][2]]
    fields = list(RECORD_FIXED.unpack_from(seq1))
    header_len = fields[4]
    head = bytearray(seq1[: header_len - 4]) + b"NEWFIELD"
    fields[2], fields[4] = 2, header_len + 8  # version, header_len
    RECORD_FIXED.pack_into(head, 0, *fields)
    newer = bytes(head) + struct.pack("<I", crc32c(bytes(head))) + seq1[header_len:]
    seg.write_bytes(data[: recs[1][1]] + newer + data[recs[1][1] + recs[1][2] :])
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 2]
        assert store.recovery.problems == []
        assert [p.reason for p in store.recovery.skipped] == ["unsupported record version"]
        assert store.put_window("/a", [(999, "1")]).seq == 3


@pytest.mark.parametrize("fields, reason", [({"kind": 0}, "bad record field"), ({"count": 0}, "bad record field"),
                                            ({"start": 50, "end": 40}, "bad record field"),
                                            ({"flags": 4}, None)])  # fmt: skip
def test_intact_records_with_impossible_fields(tmp_path, fields, reason):
    recs = make_store(tmp_path / "s")
    patch_header(tmp_path / "s" / SEG, recs[2][1], **fields)
    with cclogfs.open_store(tmp_path / "s") as store:
        if reason:  # no writer makes these: damage, the tail ends there
            assert seqs(store) == [0, 1] and store.recovery.problems[0].reason == reason
        else:  # unknown flags: a newer writer's record, skipped
            assert seqs(store) == [0, 1, 3] and store.recovery.skipped[0].reason == "unknown record flags"


def test_damage_mid_active_segment_keeps_the_bytes_and_fsck_says_error(tmp_path):
    from cclogfs.store.fsck import check_store

    recs = make_store(tmp_path / "s", n=5, sync_every_ms=0)  # every put synced
    seq, off, length = recs[1]
    flip(tmp_path / "s" / SEG, off + length - 5)  # bit rot in a synced record
    report = check_store(str(tmp_path / "s"))
    assert [f.severity for f in report.findings] == ["error"] and "3 intact records" in str(report.findings[0])
    tail = (tmp_path / "s" / SEG).read_bytes()[off:]
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0]  # still a prefix: no hole
        (p,) = store.recovery.problems
        assert p.intact_after == 3 and p.kept_in == f"{SEG}.tail-{off}"
    assert (tmp_path / "s" / f"{SEG}.tail-{off}").read_bytes() == tail  # nothing destroyed


def test_plain_torn_tail_keeps_no_side_file(tmp_path):
    recs = make_store(tmp_path / "s")
    with open(tmp_path / "s" / SEG, "r+b") as f:
        f.truncate(recs[3][1] + 30)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert store.recovery.problems[0].intact_after == 0 and not store.recovery.problems[0].kept_in
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["00000000000000000000.seg", "LOCK", "MANIFEST"]


def test_fsck_deep_reports_damaged_sealed_segment_without_index(tmp_path):
    from cclogfs.store.fsck import check_store

    make_store(tmp_path / "s", n=80, segment_bytes=4096, sync_every_bytes=1)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        w = [w for w in store.query() if w.seq == 3][0]
        off, length = w._offset, w._length
    flip(tmp_path / "s" / SEG, off + length - 3)
    (tmp_path / "s" / "00000000000000000000.idx").unlink()
    report = check_store(str(tmp_path / "s"), deep=True)
    assert report.errors and any("cannot be listed" in f.what for f in report.errors)
    assert report.decoded > 0  # the other segments were still decoded


def test_crash_while_creating_a_store(tmp_path):
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "LOCK").write_text("")
    (tmp_path / "s" / "MANIFEST.tmp").write_bytes(b"CCLM\x01")
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/a", [(0, "1")])
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0]


def test_windows_of_a_closed_store_refuse_to_read(tmp_path):
    from cclogfs.errors import StoreError

    make_store(tmp_path / "s")
    store = cclogfs.open_store(tmp_path / "s", readonly=True)
    windows = list(store.query())
    store.close()
    with pytest.raises(StoreError, match="closed"):
        list(windows[0].messages())
