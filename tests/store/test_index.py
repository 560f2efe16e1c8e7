"""The time index of one segment: overlap search, encoding, and what decode refuses."""

import random
import struct

import pytest

from cclogfs.store.format import INDEX_ENTRY, INDEX_HEADER, Reason, RecordError
from cclogfs.store.index import OFFSET, SEQ, START, SegmentIndex, merge_stream_stats


def rows(n=200, seed=1):
    rnd = random.Random(seed)
    out = []
    for seq in range(n):
        start = rnd.randrange(-1000, 1000)
        out.append((rnd.choice(["/a", "/b", "/c"]), rnd.randrange(1, 9), seq, start, start + rnd.randrange(0, 300),
                    100 + seq * 80, 80, 400))  # records of 80 bytes back to back  # fmt: skip
    return out


def test_overlapping_matches_brute_force():
    rs = rows()
    index = SegmentIndex.build(rs)
    rnd = random.Random(2)
    for _ in range(300):
        t0 = rnd.randrange(-1500, 1500)
        t1 = t0 + rnd.randrange(0, 400)
        for name in ("/a", "/b", "/c"):
            got = sorted(e[SEQ] for e in index.streams[name].overlapping(t0, t1))
            want = sorted(r[2] for r in rs if r[0] == name and r[3] <= t1 and r[4] >= t0)
            assert got == want, (name, t0, t1)


def test_entries_of_a_stream_are_sorted_by_start_then_seq():
    index = SegmentIndex.build([("/a", 1, 2, 5, 5, 0, 1, 1), ("/a", 1, 1, 5, 9, 0, 1, 1), ("/a", 1, 0, 7, 7, 0, 1, 1)])
    e = index.streams["/a"].entries
    assert [(x[START], x[SEQ]) for x in e] == [(5, 1), (5, 2), (7, 0)]
    assert list(index.streams["/a"].run_max_end) == [9, 9, 9]


def test_encode_decode_round_trip():
    index = SegmentIndex.build(rows())
    data = index.encode(first_seq=10, segment_size=20000)
    back = SegmentIndex.decode(data, 10, 20000)
    assert back.names == index.names and back.entries == index.entries
    assert back.stream_stats() == index.stream_stats()


def test_empty_index_round_trip():
    index = SegmentIndex.build([])
    assert len(SegmentIndex.decode(index.encode(0, 32), 0, 32)) == 0


def _decode_error(data, first_seq=10, size=12345):
    with pytest.raises(RecordError) as err:
        SegmentIndex.decode(data, first_seq, size)
    return err.value.reason


def test_decode_refuses_damage_with_its_reason():
    data = SegmentIndex.build(rows(20)).encode(10, 12345)
    assert _decode_error(data[:10]) == Reason.TORN
    assert _decode_error(b"XXXX" + data[4:]) == Reason.BAD_MAGIC
    assert _decode_error(data[:4] + b"\x02" + data[5:]) == Reason.UNSUPPORTED_VERSION
    assert _decode_error(data + b"\0") == Reason.BAD_LENGTH
    flipped = bytearray(data)
    flipped[INDEX_HEADER.size + 3] ^= 1
    assert _decode_error(bytes(flipped)) == Reason.PAYLOAD_HASH


def test_decode_refuses_the_index_of_another_version_of_the_segment():
    data = SegmentIndex.build(rows(20)).encode(10, 12345)
    assert _decode_error(data, size=12346) == Reason.INDEX_MISMATCH
    assert _decode_error(data, first_seq=11) == Reason.INDEX_MISMATCH


def test_decode_refuses_an_entry_naming_an_unknown_stream():
    index = SegmentIndex.build(rows(20))
    entries = list(index.entries)
    entries[0] = (7, *entries[0][1:])
    names = b'["/a","/b","/c"]'
    body = INDEX_HEADER.pack(b"CCLI", 1, 0, 10, 12345, len(entries), len(names)) + names
    body += b"".join(INDEX_ENTRY.pack(*e) for e in entries)
    from cclogfs.store.format import xxh3

    assert _decode_error(body + struct.pack("<Q", xxh3(body))) == Reason.BAD_FIELD


def test_stream_stats_and_merge():
    rs = [("/a", 3, 0, 10, 20, 32, 100, 80), ("/a", 2, 1, 5, 30, 132, 60, 50), ("/b", 1, 2, 0, 0, 192, 40, 30)]
    stats = SegmentIndex.build(rs).stream_stats()
    assert stats["/a"] == {"windows": 2, "messages": 5, "start_ns": 5, "end_ns": 30, "raw_bytes": 130,
                           "stored_bytes": 160}  # fmt: skip
    total = {}
    merge_stream_stats(total, stats)
    merge_stream_stats(total, {"/a": {"windows": 1, "messages": 1, "start_ns": -4, "end_ns": 2, "raw_bytes": 1,
                                      "stored_bytes": 2}})  # fmt: skip
    assert total["/a"] == {"windows": 3, "messages": 6, "start_ns": -4, "end_ns": 30, "raw_bytes": 131,
                           "stored_bytes": 162}  # fmt: skip
    assert total["/b"] == stats["/b"] and total["/b"] is not stats["/b"]  # copied, not aliased
    assert all(e[OFFSET] > 0 for e in SegmentIndex.build(rs).entries)


def test_golden_indexes_encode_back_byte_for_byte():
    # The index was written through numpy before issue 14: the same entries, the same bytes.
    from pathlib import Path

    paths = sorted((Path(__file__).parent.parent / "golden").glob("store_v*/*.idx"))
    assert paths
    for path in paths:
        data = path.read_bytes()
        _magic, _v, _f, first_seq, size, _count, _names_len = INDEX_HEADER.unpack_from(data)
        assert SegmentIndex.decode(data, first_seq, size).encode(first_seq, size) == data, path
