"""Texts whose last value is followed by a key (`..., "intensities": []}`) have a shape.

The tokenizer's findall used to search on inside such a tail and cut the key's letters as
a number, so the text had no shape and the codec stored it verbatim: a LaserScan without
intensities took 2.4x the bytes (bench/laser_scans.py, see docs/CODEC_COLUMNAR.md).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cclogfs.codecs import raw_size
from cclogfs.codecs.columnar import ColumnarCodec
from cclogfs.codecs.columnar_format import FORMAT_VERSIONS, HEADER, RAW_GROUP
from cclogfs.codecs.shapes import ShapeMatcher, split_text

GOLDEN = Path(__file__).parent.parent / "golden" / "columnar" / "v4-keyed-tail"

# Every test here runs on both row paths (tests/conftest.py: row_path).
pytestmark = pytest.mark.usefixtures("row_path")


def raw_messages(data: bytes, count: int) -> int:
    """How many messages of a columnar payload are stored verbatim (group id 0xFFFF)."""
    body = zstandard.ZstdDecompressor().decompress(data[HEADER.size :])
    ids = struct.unpack_from(f"<{count}H", body, 4)  # after the u32 group count
    return ids.count(RAW_GROUP)


def encode_checked(texts: list[str], version: int = FORMAT_VERSIONS[-1]) -> bytes:
    stamps = list(range(len(texts)))
    codec = ColumnarCodec(version=version)
    data = codec.encode(stamps, texts)
    assert codec.decode(data, count=len(texts), raw_len=raw_size(stamps, texts)) == (stamps, texts)
    return data


@pytest.mark.parametrize(
    "text, literals, values",
    [
        ('{"a": 1, "b": []}', ('{"a": ', ', "b": []}'), ["1"]),
        ('{"a": "x", "b": {}, "c": [[]]}\n', ('{"a": ', ', "b": {}, "c": [[]]}\n'), ['"x"']),
        ('{"a": []}', ('{"a": []}',), []),
        ('{"a" :\t{"b": [ ]} }', ('{"a" :\t{"b": [ ]} }',), []),
        ('[1, {"k": []}]', ("[", ', {"k": []}]'), ["1"]),
    ],
)
def test_a_key_after_the_last_value_is_literal_text(text, literals, values):
    assert split_text(text) == (literals, values)


@pytest.mark.parametrize("text", ['{"a": 1, "b": [] $}', '{"a": 1, "b: []}', '{"a": [1, "b: 1]}'])
def test_a_tail_that_is_not_literal_text_still_has_no_shape(text):
    # Garbage after the key, a key cut short, a string cut short after it:
    # the tail is not punctuation and keys alone, so nothing is guessed.
    assert split_text(text) is None


def scan(i: int, intensities: list[float]) -> str:
    """A LaserScan as rosbridge JSON: the empty `intensities` is its last key."""
    ranges = [round(1.0 + ((i * 7 + b * 13) % 97) / 50, 3) for b in range(90)]
    msg = {
        "header": {"stamp": {"sec": i // 5, "nanosec": i % 5 * 200_000_000}, "frame_id": "base_scan"},
        "angle_min": 0.0, "angle_max": 6.2831854820251465, "angle_increment": 0.01745329238474369,
        "time_increment": 0.0, "scan_time": 0.0, "range_min": 0.11999999731779099, "range_max": 3.5,
        "ranges": ranges, "intensities": intensities,
    }  # fmt: skip
    return json.dumps(msg)


@pytest.mark.parametrize("version", FORMAT_VERSIONS)
def test_a_laser_scan_without_intensities_is_stored_in_columns(version):
    texts = [scan(i, []) for i in range(50)]
    data = encode_checked(texts, version)
    assert raw_messages(data, len(texts)) == 0
    # As small as the same scans with one intensity (a value after every key), not more.
    with_value = encode_checked([scan(i, [0.0]) for i in range(50)], version)
    assert len(data) <= len(with_value)


def test_the_golden_case_holds_these_texts_in_columns():
    # tests/codecs/test_columnar.py decodes it with the other golden payloads.
    count = len((GOLDEN / "inputs.jsonl").read_text().splitlines())
    assert raw_messages((GOLDEN / "encoded.bin").read_bytes(), count) == 0


# --- empty arrays and objects at every position --------------------------------------------

numbers = st.integers(-(10**6), 10**6) | st.floats(allow_nan=False)
leaves = st.none() | st.booleans() | numbers | st.text(max_size=6)
empties = st.sampled_from([[], {}, [[]], {"e": []}, [{}, []]])


@st.composite
def keyed_windows(draw) -> list[str]:
    """Messages of one key order whose values vary, with empty containers at drawn
    positions (the first, the last, anywhere, or every one) that stay empty in each."""
    keys = draw(st.lists(st.text(max_size=4), min_size=1, max_size=6, unique=True))
    where = draw(st.sampled_from(["first", "last", "any", "all"]))
    if where == "any":
        empty_at = set(draw(st.lists(st.integers(0, len(keys) - 1), min_size=1)))
    else:
        empty_at = {"first": {0}, "last": {len(keys) - 1}, "all": set(range(len(keys)))}[where]
    shapes = {j: draw(empties) for j in empty_at}
    n = draw(st.integers(1, 12))
    nested = draw(st.booleans())  # the object one level down, as a ROS message's fields are
    indent = draw(st.sampled_from([None, 1]))
    texts = []
    for _ in range(n):
        row = {k: shapes[j] if j in shapes else draw(leaves) for j, k in enumerate(keys)}
        texts.append(json.dumps({"msg": row, "tail": []} if nested else row, indent=indent))
    return texts


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(keyed_windows(), st.sampled_from(FORMAT_VERSIONS))
def test_empty_containers_at_any_position_round_trip_in_columns(texts, version):
    for text in texts:
        literals, values = split_text(text)
        assert "".join(a + b for a, b in zip(literals, values + [""])) == text
    data = encode_checked(texts, version)
    assert raw_messages(data, len(texts)) == 0


@settings(max_examples=100, deadline=None)
@given(
    st.recursive(
        st.none() | st.integers() | st.text(max_size=3),
        lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=3), inner, max_size=3),
        max_leaves=12,
    )
)
def test_every_json_dumps_text_has_a_shape(value):
    text = json.dumps(value)
    groups, unshaped = ShapeMatcher().group_window([text])
    assert unshaped == [] and len(groups) == 1
