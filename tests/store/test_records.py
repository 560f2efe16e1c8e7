"""The one record reader: framing and checksums (read_record), log order (records)."""

import pytest

from cclogfs.store.format import (
    RECORD_FIXED_SIZE,
    Reason,
    RecordError,
    pack_record,
)
from cclogfs.store.records import BytesAt, ChunkReader, count_intact_in, read_record, records
from cclogfs.store import records as records_module
from cclogfs.store.fs import FileSystem


def rec(seq, payload=b"payload!", name=b"/a", **kw):
    fields = dict(seq=seq, start_ns=10 * seq, end_ns=10 * seq + 5, count=2, codec=1, name=name,
                  config=b'{"id":"none"}', meta=b"{}", raw_len=len(payload), payload=payload)  # fmt: skip
    fields.update(kw)
    return pack_record(**fields)


def log(n, start=0):
    return b"".join(rec(start + i, payload=bytes([i]) * (10 + i)) for i in range(n))


def test_read_record_returns_header_and_payload():
    data = b"xx" + rec(3, b"hello")
    header, payload = read_record(BytesAt(data), 2, len(data) - 2)
    assert (header.seq, header.name, bytes(payload), header.record_len) == (3, "/a", b"hello", len(data) - 2)


def _damaged(data, at, value):
    data = bytearray(data)
    data[at] = value if isinstance(value, int) else data[at]
    return bytes(data)


@pytest.mark.parametrize("damage, reason", [
    (lambda r: r[:-3], Reason.TORN),
    (lambda r: r[:30], Reason.TORN),
    (lambda r: bytes(len(r)), Reason.ZERO_FILL),
    (lambda r: b"XCLR" + r[4:], Reason.BAD_MAGIC),
    (lambda r: _damaged(r, RECORD_FIXED_SIZE + 1, r[RECORD_FIXED_SIZE + 1] ^ 1), Reason.HEADER_CRC),
    (lambda r: _damaged(r, len(r) - 1, r[-1] ^ 1), Reason.PAYLOAD_HASH),
])  # fmt: skip
def test_read_record_names_the_reason_and_the_offset(damage, reason):
    data = b"\0" * 7 + damage(rec(0))
    with pytest.raises(RecordError) as err:
        read_record(BytesAt(data), 7, len(data) - 7)
    assert (err.value.reason, err.value.offset) == (reason, 7)


def test_a_length_over_its_limit_is_refused_before_reading_it():
    import struct

    data = bytearray(rec(0))
    struct.pack_into("<Q", data, RECORD_FIXED_SIZE - 16, 1 << 40)  # enc_len
    with pytest.raises(RecordError) as err:
        read_record(BytesAt(bytes(data)), 0, len(data))
    assert err.value.reason == Reason.BAD_LENGTH


def test_records_walks_in_log_order():
    data = log(5, start=7)
    got = [(r.offset, r.header.seq, r.skip) for r in records(BytesAt(data), 0, len(data), 7)]
    assert [g[1] for g in got] == [7, 8, 9, 10, 11] and all(g[2] is None for g in got)
    assert got[0][0] == 0 and got[1][0] == len(rec(7, payload=bytes([0]) * 10))


def test_records_stops_at_a_sequence_gap_with_its_offset():
    data = rec(0) + rec(2)
    walked = []
    with pytest.raises(RecordError) as err:
        for r in records(BytesAt(data), 0, len(data), 0):
            walked.append(r.header.seq)
    assert walked == [0] and (err.value.reason, err.value.offset) == (Reason.SEQ_GAP, len(rec(0)))


def test_records_reports_an_unknown_kind_as_a_skip():
    data = rec(0) + rec(1, kind=9) + rec(2)
    assert [r.skip for r in records(BytesAt(data), 0, len(data), 0)] == [None, Reason.UNKNOWN_KIND, None]


def test_records_refuses_impossible_fields():
    data = rec(0, count=0)
    with pytest.raises(RecordError) as err:
        list(records(BytesAt(data), 0, len(data), 0))
    assert err.value.reason == Reason.BAD_FIELD


def _count(tmp_path, data: bytes, start: int = 0) -> int:
    path = tmp_path / "f"
    path.write_bytes(data)
    fs = FileSystem()
    fd = fs.open(str(path))
    try:
        return count_intact_in(fs, fd, start, len(data))
    finally:
        fs.close(fd)


def test_count_intact_finds_records_past_damage(tmp_path):
    data = bytearray(log(6))
    first = len(rec(0, payload=bytes([0]) * 10))
    data[first + 5] ^= 0xFF  # record 1's header
    assert _count(tmp_path, bytes(data[first:]), 1) == 4
    assert _count(tmp_path, bytes(data), first + 1) == 4
    assert _count(tmp_path, b"garbage" * 10) == 0


def test_count_intact_finds_a_magic_across_search_chunks(tmp_path, monkeypatch):
    # A record whose magic straddles two search chunks is found all the same.
    monkeypatch.setattr(records_module, "SEARCH_CHUNK", 7)
    data = log(6)
    for pad in range(8):
        assert _count(tmp_path, b"x" * pad + data) == 6


def test_chunk_reader_reads_like_pread_across_chunks(tmp_path, monkeypatch):
    monkeypatch.setattr(ChunkReader, "CHUNK", 64)
    data = bytes(range(256)) * 4
    (tmp_path / "f").write_bytes(data)
    fs = FileSystem()
    fd = fs.open(str(tmp_path / "f"))
    try:
        reader = ChunkReader(fs, fd)
        for offset, n in [(0, 10), (60, 10), (5, 3), (100, 200), (1000, 50), (1020, 10)]:
            assert reader.read(offset, n) == data[offset : offset + n]
    finally:
        fs.close(fd)
