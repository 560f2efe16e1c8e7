"""The physical layout (mirror of docs/FORMAT.md): headers, records, names, manifest."""

import re
from pathlib import Path

import pytest

from cclogfs.store.format import (
    MANIFEST_HEADER,
    RECORD_FIXED_SIZE,
    SEGMENT_HEADER_SIZE,
    Reason,
    RecordError,
    check_fields,
    check_fixed,
    index_name,
    pack_manifest,
    pack_record,
    pack_segment_header,
    parse_header,
    parse_seq_name,
    segment_name,
    unpack_manifest,
    unpack_segment_header,
)

FORMAT_MD = Path(__file__).resolve().parents[2] / "docs" / "FORMAT.md"


def test_fixed_sizes_are_the_documented_ones():
    assert RECORD_FIXED_SIZE == 74 and SEGMENT_HEADER_SIZE == 32


def test_segment_header_round_trip_and_damage():
    head = pack_segment_header(42, -5)
    assert unpack_segment_header(head) == (42, -5)
    assert unpack_segment_header(head[:-1]) is None
    for i in range(len(head)):
        bad = bytearray(head)
        bad[i] ^= 1
        assert unpack_segment_header(bytes(bad)) is None, i


def test_record_round_trip():
    record = pack_record(seq=9, start_ns=-3, end_ns=4, count=2, codec=1, name="/é".encode(), config=b"{}",
                         meta=b'{"m":1}', raw_len=5, payload=b"abcde", flags=1)  # fmt: skip
    header_len = check_fixed(record[:RECORD_FIXED_SIZE], len(record))
    header = parse_header(record[:header_len])
    assert (header.seq, header.start_ns, header.end_ns, header.count, header.name, header.meta, header.flags) == (
        9, -3, 4, 2, "/é", b'{"m":1}', 1)
    assert header.record_len == len(record) and check_fields(header) is None


def test_a_stream_name_that_is_not_utf8_is_a_bad_field():
    record = pack_record(seq=0, start_ns=0, end_ns=0, count=1, codec=1, name=b"\xff", config=b"{}",
                         meta=b"{}", raw_len=1, payload=b"x")  # fmt: skip
    with pytest.raises(RecordError) as err:
        parse_header(record[: check_fixed(record[:RECORD_FIXED_SIZE], len(record))])
    assert err.value.reason == Reason.BAD_FIELD


def test_file_names():
    assert segment_name(7) == "00000000000000000007.seg" and index_name(7, 2) == "00000000000000000007-2.idx"
    assert parse_seq_name(segment_name(7, 3)) == (7, "seg", 3)
    assert parse_seq_name(index_name(0)) == (0, "idx", 0)
    for name in ("MANIFEST", "00000000000000000007-0.seg", "7.seg", "00000000000000000007.seg.tail-40"):
        assert parse_seq_name(name) is None, name


def test_manifest_round_trip_and_damage():
    data = pack_manifest({"b": 1, "a": [1, 2]})
    assert unpack_manifest(data) == {"a": [1, 2], "b": 1}
    cases = [(data[:5], Reason.TORN), (b"XXXX" + data[4:], Reason.BAD_MAGIC),
             (data + b"x", Reason.BAD_LENGTH), (data[:-1] + bytes([data[-1] ^ 1]), Reason.HEADER_CRC),
             (data[:4] + b"\x02" + data[5:], Reason.UNSUPPORTED_VERSION)]  # fmt: skip
    for bad, reason in cases:
        with pytest.raises(RecordError) as err:
            unpack_manifest(bad)
        assert err.value.reason == reason
    assert MANIFEST_HEADER.size == 12


def _reasons():
    return {k: v for k, v in vars(Reason).items() if not k.startswith("_")}


def test_reasons_are_distinct():
    values = list(_reasons().values())
    assert len(values) == len(set(values))


def test_format_md_lists_every_reason_once():
    text = FORMAT_MD.read_text()
    section = text[text.index("## Reject reasons") :]
    section = section[: section.index("\n## ")]
    listed = re.findall(r"^\| `([^`]+)` \|", section, re.M)
    assert sorted(listed) == sorted(_reasons().values())
