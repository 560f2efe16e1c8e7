"""One test per corruption rule: what survives, and the reason reported."""

import struct

from cclogfs.store.format import Reason, segment_name

import pytest

import cclogfs
from cclogfs.errors import CorruptionError, DamagedError, UnknownCodecError
from cclogfs.store.format import RECORD_FIXED, RECORD_FIXED_SIZE, crc32c
from helpers import SEG, append, cut, drop_checkpoint, flip, forge_index_offsets, make_store, patch_header, segment_files, seqs, unseal

def test_torn_tail_is_truncated_and_reported(tmp_path):
    recs = make_store(tmp_path / "s")
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    seg = tmp_path / "s" / SEG
    size = recs[3][1] + recs[3][2] // 2
    cut(seg, size)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1, 2]
        (p,) = store.recovery.problems
        assert (p.reason, p.offset, p.dropped_bytes) == ("torn record", recs[3][1], size - recs[3][1])
    assert seg.stat().st_size == recs[3][1]


@pytest.mark.parametrize("where, reason", [("payload", "payload checksum mismatch"),
                                           ("header", "header checksum mismatch")])  # fmt: skip
def test_checksum_mismatch_ends_the_tail(tmp_path, where, reason):
    recs = make_store(tmp_path / "s")
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    seq, off, length = recs[1]
    flip(tmp_path / "s" / SEG, off + (length - 5 if where == "payload" else RECORD_FIXED_SIZE + 1))
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0]  # nothing after the damage: no hole
        (p,) = store.recovery.problems
        assert (p.reason, p.offset) == (reason, off)


def test_bad_length_is_caught_before_allocating(tmp_path):
    recs = make_store(tmp_path / "s")
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    patch_header(tmp_path / "s" / SEG, recs[2][1], enc_len=1 << 40)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1]
        assert store.recovery.problems[0].reason == "bad record length"


def test_zero_fill(tmp_path):
    recs = make_store(tmp_path / "s")
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    append(tmp_path / "s" / SEG, b"\0" * 4096)
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
        with pytest.raises(CorruptionError, match="names codec 77") as err:
            list(bad.messages())
        assert err.value.reason == "codec mismatch"
        assert len(list([w for w in store.query() if w.seq == 2][0].messages())) == 20


def test_unknown_codec_id_in_config(tmp_path):
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, codec="zstd") as store:
        store.put_window("/a", [(0, "1")])
        (w,) = store.query()
        offset = w.offset
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
        path, off = first.segment_path, first.offset
    flip(path, off + first.stored_bytes - 3)
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
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    seg = tmp_path / "s" / SEG
    cut(seg, recs[3][1] + 10)
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
        boundary = [w for w in store.query() if w.seq == first.next_seq - 2][0].offset
        expected_seqs = [w.seq for w in store.query()]
    cut(tmp_path / "s" / SEG, boundary)
    lost = [first.next_seq - 2, first.next_seq - 1]
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        # The cut is damage below the synced point: a query refuses, naming the seqs it lost.
        with pytest.raises(DamagedError, match=f"seqs {lost[0]}..{lost[1]}"):
            list(store.query())
        assert [w.seq for w in store.query(skip_damaged=True)] == [s for s in expected_seqs if s not in lost]
    with pytest.raises(DamagedError, match="a writer cannot open the store"):
        cclogfs.open_store(tmp_path / "s")


def test_record_of_a_newer_version_with_a_longer_header_is_skipped(tmp_path):
    # A version 9 that appends 8 bytes to the header (allowed by the extension rules): this
    # reader frames it by header_len, skips it, and keeps every later record.
    from cclogfs.store.format import RECORD_FIXED

    recs = make_store(tmp_path / "s", n=3)
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    seg = tmp_path / "s" / SEG
    data = seg.read_bytes()
    seq1 = data[recs[1][1] : recs[1][1] + recs[1][2]]
    fields = list(RECORD_FIXED.unpack_from(seq1))
    header_len = fields[4]
    head = bytearray(seq1[: header_len - 4]) + b"NEWFIELD"
    fields[2], fields[4] = 9, header_len + 8  # version, header_len
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
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    patch_header(tmp_path / "s" / SEG, recs[2][1], **fields)
    with cclogfs.open_store(tmp_path / "s") as store:
        if reason:  # no writer makes these: damage, the tail ends there
            assert seqs(store) == [0, 1] and store.recovery.problems[0].reason == reason
        else:  # unknown flags: a newer writer's record, skipped
            assert seqs(store) == [0, 1, 3] and store.recovery.skipped[0].reason == "unknown record flags"


def test_damage_below_the_synced_point_is_kept_declared_and_never_hidden(tmp_path):
    # Issue 11, item 1: a clean close, one flipped byte mid-segment. Recovery must not cut the
    # intact records after it, and a second write must not hide the damage.
    from cclogfs.errors import DamagedError

    recs = make_store(tmp_path / "s", n=5)
    seq, off, length = recs[1]
    flip(tmp_path / "s" / SEG, off + length - 5)  # bit rot in a synced record
    for _ in range(2):  # the second open (after a further put) still sees and names it
        with cclogfs.open_store(tmp_path / "s") as store:
            (d,) = store.damage()
            assert (d["segment"], d["offset"], d["first_seq"], d["end_seq"]) == (SEG, off, 1, 2)
            assert d["reason"] == "payload checksum mismatch" and d["length"] == length
            with pytest.raises(DamagedError, match="seq 1: payload checksum mismatch"):
                list(store.query())
            got = [w.seq for w in store.query(skip_damaged=True)]
            assert got[:4] == [0, 2, 3, 4]  # every intact window, none cut
            store.put_window("/a", [(999, "1")])
    assert not list((tmp_path / "s").glob("*.tail-*"))
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [w.seq for w in store.query(skip_damaged=True)] == [0, 2, 3, 4, 5, 6]


def test_damage_in_the_last_synced_group_is_not_a_torn_tail(tmp_path):
    # The checkpoint of a clean close proves the last group durable: damage there is kept.
    recs = make_store(tmp_path / "s", n=4)
    seq, off, length = recs[3]
    flip(tmp_path / "s" / SEG, off + length - 5)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert [(d["first_seq"], d["end_seq"]) for d in store.damage()] == [(3, 4)]
        assert store.put_window("/a", [(999, "1")]).seq == 4  # seq 3 is never reused
    assert (tmp_path / "s" / SEG).stat().st_size == off + length  # nothing cut


def test_plain_torn_tail_keeps_no_side_file(tmp_path):
    recs = make_store(tmp_path / "s")
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    cut(tmp_path / "s" / SEG, recs[3][1] + 30)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert store.recovery.problems[0].intact_after == 0 and not store.recovery.problems[0].kept_in
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["00000000000000000000.idx", "00000000000000000000.seg", "LOCK",
                                                                          "MANIFEST", "RESERVE"]  # fmt: skip


def test_fsck_deep_reports_damaged_sealed_segment_without_index(tmp_path):
    from cclogfs.store import check_store

    make_store(tmp_path / "s", n=80, segment_bytes=4096, sync_every_bytes=1)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        w = [w for w in store.query() if w.seq == 3][0]
        off, length = w.offset, w.stored_bytes
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


# -- one scenario per reject reason not covered above ----------------------------------------


def test_bad_magic_ends_the_tail(tmp_path):
    recs = make_store(tmp_path / "s")
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    flip(tmp_path / "s" / SEG, recs[2][1])  # first byte of the record's magic
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1]
        (p,) = store.recovery.problems
        assert (p.reason, p.offset) == (Reason.BAD_MAGIC, recs[2][1])


def test_sequence_gap_inside_a_segment_ends_the_tail(tmp_path):
    recs = make_store(tmp_path / "s")
    drop_checkpoint(tmp_path / "s")  # a crash after the last put: its tail is unsynced
    patch_header(tmp_path / "s" / SEG, recs[2][1], seq=7)  # intact, but not the next seq
    with cclogfs.open_store(tmp_path / "s") as store:
        assert seqs(store) == [0, 1]
        (p,) = store.recovery.problems
        assert (p.reason, p.offset) == (Reason.SEQ_GAP, recs[2][1])
        assert store.put_window("/a", [(999, "1")]).seq == 2


def _three_segments(path):
    """A store whose manifest names one sealed segment; two more segments form the tail."""
    make_store(path, n=30, segment_records=10, sync_every_bytes=1)
    files = segment_files(path)
    assert len(files) == 4  # 0, 10, 20 sealed; 30 active (empty)
    unseal(path, keep=1)
    return files


def test_tail_segment_that_does_not_start_where_the_log_ends_is_a_gap(tmp_path):
    files = _three_segments(tmp_path / "s")
    files[1].unlink()  # the tail's first segment is lost: the next one starts too late
    with cclogfs.open_store(tmp_path / "s") as store:
        reasons = [(p.path.rsplit("/", 1)[1], p.reason) for p in store.recovery.problems]
        assert reasons[0] == (files[2].name, Reason.SEQ_GAP)
        assert all(r == Reason.DROPPED_SEGMENT for _, r in reasons[1:])
        assert store.sealed[-1].next_seq == max(seqs(store)) + 1  # nothing after the gap kept


def test_bad_segment_header_drops_the_segment_and_all_after_it(tmp_path):
    files = _three_segments(tmp_path / "s")
    files[1].write_bytes(b"\0" * 32)  # created, its header never reached the disk, no record
    with cclogfs.open_store(tmp_path / "s") as store:
        got = [(p.path.rsplit("/", 1)[1], p.reason) for p in store.recovery.problems]
        assert got[0] == (files[1].name, Reason.BAD_SEGMENT_HEADER)
        assert got[1:] == [(f.name, Reason.DROPPED_SEGMENT) for f in files[2:]]
        assert seqs(store) == list(range(10)) and store.active_first_seq == 10  # a new, empty segment 10
    assert not files[2].exists() and not files[3].exists()


def test_a_damaged_header_before_synced_records_is_damage_not_an_empty_tail(tmp_path):
    # Issue 11, item 6: one flipped bit in the active header used to delete the segment.
    files = _three_segments(tmp_path / "s")
    flip(files[1], 9)
    with cclogfs.open_store(tmp_path / "s") as store:
        (d,) = store.damage()
        assert (d["segment"], d["offset"], d["reason"]) == (files[1].name, 0, Reason.BAD_SEGMENT_HEADER)
        assert [w.seq for w in store.query(skip_damaged=True)] == list(range(30))
    assert files[1].exists()


def test_segment_after_the_torn_tail_is_dropped(tmp_path):
    files = _three_segments(tmp_path / "s")
    cut(files[1], files[1].stat().st_size - 7)  # torn last record in the tail's first segment
    with cclogfs.open_store(tmp_path / "s") as store:
        got = [(p.path.rsplit("/", 1)[1], p.reason) for p in store.recovery.problems]
        assert got[0] == (files[1].name, Reason.TORN)
        assert got[1:] == [(f.name, Reason.DROPPED_SEGMENT) for f in files[2:]]
        assert seqs(store) == list(range(len(seqs(store))))  # a prefix, no hole


def test_stray_segment_before_the_end_of_the_log_is_ignored(tmp_path):
    make_store(tmp_path / "s", n=30, segment_bytes=4096, sync_every_bytes=1)
    stray = tmp_path / "s" / segment_name(1)  # inside the first sealed segment's seqs
    stray.write_bytes((tmp_path / "s" / SEG).read_bytes())
    with cclogfs.open_store(tmp_path / "s") as store:
        (p,) = store.recovery.problems
        assert (p.path, p.reason) == (str(stray), Reason.STRAY_SEGMENT)
        assert seqs(store) == list(range(30))
    assert stray.exists()  # not ours to touch


def test_missing_segment_reason(tmp_path):
    make_store(tmp_path / "s", n=30, segment_bytes=4096, sync_every_bytes=1)
    (tmp_path / "s" / SEG).unlink()
    with pytest.raises(CorruptionError) as err:
        cclogfs.open_store(tmp_path / "s")
    assert err.value.reason == Reason.MISSING_SEGMENT


def test_sealed_segment_of_another_size_reason(tmp_path):
    make_store(tmp_path / "s", n=30, segment_bytes=4096, sync_every_bytes=1)
    append(tmp_path / "s" / SEG, b"\0" * 10)
    (tmp_path / "s" / "00000000000000000000.idx").unlink()
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        with pytest.raises(CorruptionError, match="manifest says it was sealed at") as err:
            list(store.query())
        assert err.value.reason == Reason.SIZE_MISMATCH


def test_record_of_another_length_than_its_index_entry(tmp_path):
    # A sealed segment whose index points at a record with another length than it has.

    from cclogfs.store.index import SegmentIndex

    make_store(tmp_path / "s", n=30, segment_bytes=4096, sync_every_bytes=1)
    idx_path = tmp_path / "s" / "00000000000000000000.idx"
    size = (tmp_path / "s" / SEG).stat().st_size
    index = SegmentIndex.decode(idx_path.read_bytes(), 0, size)
    entries = list(index.entries)
    stream, count, seq, start, end, offset, length, raw_len = entries[1]
    entries[1] = (stream, count, seq, start, end, offset, length + 1, raw_len)
    idx_path.write_bytes(SegmentIndex(index.names, entries).encode(0, size))
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        (w,) = [w for w in store.query() if w.seq == seq]
        with pytest.raises(CorruptionError) as err:
            list(w.messages())
        assert err.value.reason == Reason.INDEX_MISMATCH


def test_message_that_is_not_utf8_is_an_error_on_read_and_in_fsck(tmp_path):
    # A payload with a valid checksum whose text is not UTF-8 (a forged record, or one a
    # buggy writer made): the store only ever stores UTF-8, so reading it must fail, naming
    # the record, and `fsck --deep` must say so; never a changed text handed out as intact.
    from cclogfs.errors import CodecError
    from cclogfs.store import check_store
    from cclogfs.store.format import xxh3

    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, codec="none") as store:
        store.put_window("/a", [(1, '{"a":"xyzw"}'), (2, '{"a":"qqqq"}')])
        (w,) = store.query()
        offset = w.offset
    data = bytearray((path / SEG).read_bytes())
    i = data.index(b"xyzw", offset)
    data[i] = 0xFF
    (path / SEG).write_bytes(bytes(data))
    fields = RECORD_FIXED.unpack_from(data, offset)
    header_len, enc_len = fields[4], fields[14]
    payload = bytes(data[offset + header_len : offset + header_len + enc_len])
    patch_header(path / SEG, offset, xxh3=xxh3(payload))  # the checksums hold: only the text is wrong
    with cclogfs.open_store(path, readonly=True) as store:
        (w,) = store.query()
        with pytest.raises(CodecError, match=f"offset {offset}: message 0 is not valid UTF-8"):
            list(w.messages())
    report = check_store(str(path), deep=True)
    assert any("not valid UTF-8" in f.what for f in report.errors)


def test_a_forged_index_is_caught_on_read(tmp_path):
    # Issue 11, item 10, at the library: an index with a valid checksum naming the wrong
    # records must not hand out another window's messages.
    make_store(tmp_path / "s", n=6, segment_records=3)
    forge_index_offsets(tmp_path / "s", SEG)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        w = next(w for w in store.query() if w.seq == 0)
        with pytest.raises(CorruptionError, match="the time index says") as err:
            list(w.messages())
        assert err.value.reason == Reason.INDEX_MISMATCH
        # The mismatch rebuilt the index: the next query answers right.
        assert [(w.seq, list(w.messages())[0][0]) for w in store.query()] == [(i, i * 10) for i in range(6)]
    with cclogfs.open_store(tmp_path / "s") as store:  # a writer writes the rebuilt index back
        with pytest.raises(CorruptionError, match="the time index says"):
            [list(w.messages()) for w in store.query()]
        assert [(w.seq, list(w.messages())[0][0]) for w in store.query()] == [(i, i * 10) for i in range(6)]
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [(w.seq, list(w.messages())[0][0]) for w in store.query()] == [(i, i * 10) for i in range(6)]


def test_a_deleted_active_segment_is_missing_not_an_empty_tail(tmp_path):
    # Issue 11, item 11: the active segment's file could be deleted without anyone noticing.
    from cclogfs.store import check_store

    make_store(tmp_path / "s", n=3)
    (tmp_path / "s" / SEG).unlink()
    for opts in ({}, {"readonly": True}):
        with pytest.raises(CorruptionError, match="seqs 0..2 at the last clean close, is missing") as err:
            cclogfs.open_store(tmp_path / "s", **opts)
        assert err.value.reason == Reason.MISSING_SEGMENT
    assert check_store(str(tmp_path / "s")).errors
    # The active segment's checkpoint index is left: fsck names it as an index of no segment.
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == ["00000000000000000000.idx", "LOCK", "MANIFEST", "RESERVE"]
