"""One segment file: the append buffer, reads through the index, the scan recovery uses."""

import pytest

from cclogfs.errors import CorruptionError
from cclogfs.store import segment as segment_module
from cclogfs.store.format import SEGMENT_HEADER_SIZE, Reason, pack_record, pack_segment_header
from cclogfs.store.fs import FileSystem
from cclogfs.store.segment import Segment, intact_after, open_segment, scan
from helpers import cut, flip


def record(seq, n=30):
    payload = bytes([seq % 256]) * n
    return pack_record(seq=seq, start_ns=seq, end_ns=seq + 1, count=1, codec=1, name=b"/a", config=b"{}",
                       meta=b"{}", raw_len=n, payload=payload)  # fmt: skip


def new_segment(tmp_path, first_seq=5):
    fs = FileSystem()
    path = str(tmp_path / "seg")
    fd = fs.open(path, write=True, create=True)
    fs.pwrite(fd, pack_segment_header(first_seq, 123), 0)
    return Segment(fs, path, first_seq, 123, fd, SEGMENT_HEADER_SIZE)


def fill(seg, n):
    offsets = []
    for i in range(n):
        data = record(seg.next_seq)
        offsets.append((seg.end, len(data)))
        seg.append(data, ("/a", 1, seg.next_seq, seg.next_seq, seg.next_seq + 1, seg.end, len(data), 30))
    return offsets


def test_buffered_records_are_read_from_memory_then_from_the_file(tmp_path):
    seg = new_segment(tmp_path)
    (off, length), = fill(seg, 1)
    assert seg.size == SEGMENT_HEADER_SIZE and seg.pending  # not handed to the OS yet
    assert seg.read_record(off, length)[0].seq == 5
    seg.flush()
    assert not seg.pending and seg.size == off + length
    assert (tmp_path / "seg").stat().st_size == seg.size
    assert seg.read_record(off, length)[1] == bytes([5]) * 30


def test_a_full_buffer_is_handed_to_the_os(tmp_path, monkeypatch):
    monkeypatch.setattr(segment_module, "WRITE_BUFFER", 300)
    seg = new_segment(tmp_path)
    fill(seg, 5)
    assert seg.size > SEGMENT_HEADER_SIZE and len(seg.pending) < 300


def test_read_record_refuses_a_length_the_record_does_not_have(tmp_path):
    seg = new_segment(tmp_path)
    (off, length), _ = fill(seg, 2)
    with pytest.raises(CorruptionError) as err:
        seg.read_record(off, length + 1)
    assert err.value.reason == Reason.INDEX_MISMATCH and err.value.offset == off
    seg.flush()
    flip(seg.path, off + length - 1)
    with pytest.raises(CorruptionError, match=f"record at offset {off} is damaged") as err:
        seg.read_record(off, length)
    assert err.value.reason == Reason.PAYLOAD_HASH


def test_scan_returns_the_valid_prefix(tmp_path):
    seg = new_segment(tmp_path)
    offsets = fill(seg, 4)
    seg.flush()
    result = scan(seg)
    assert result.problem is None and result.next_seq == 9 and result.end == seg.size
    assert [r[2] for r in result.rows] == [5, 6, 7, 8] and [r[5] for r in result.rows] == [o for o, _ in offsets]
    cut(seg.path, offsets[3][0] + 10)
    seg, _ok = open_segment(FileSystem(), seg.path, write=False)  # a scan covers the size it was opened at
    result = scan(seg)
    assert result.next_seq == 8 and result.end == offsets[3][0]
    assert (result.problem.reason, result.problem.offset, result.problem.dropped_bytes) == (Reason.TORN, offsets[3][0], 10)


def test_intact_after_counts_records_past_damage(tmp_path):
    seg = new_segment(tmp_path)
    offsets = fill(seg, 6)
    seg.flush()
    flip(seg.path, offsets[1][0] + 3)  # record 1's magic
    result = scan(seg)
    assert result.problem.reason == Reason.BAD_MAGIC
    assert intact_after(seg, result.problem.offset) == 4
    assert intact_after(seg, offsets[5][0]) == 0  # the last record itself is never counted


def test_open_segment_says_whether_the_header_is_intact(tmp_path):
    seg = new_segment(tmp_path, first_seq=77)
    seg.fs.close(seg.fd)
    opened, ok = open_segment(FileSystem(), seg.path, write=False)
    assert ok and opened.first_seq == 77 and opened.created_ns == 123
    opened.fs.close(opened.fd)
    flip(seg.path, 10)
    opened, ok = open_segment(FileSystem(), seg.path, write=False)
    assert not ok and opened.first_seq == -1
    opened.fs.close(opened.fd)
