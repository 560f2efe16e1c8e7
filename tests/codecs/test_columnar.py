"""The columnar codec: byte-exact round trips, golden payloads, real data, corruption."""

from __future__ import annotations

import base64
import json
import math
import random
import struct
from pathlib import Path

import numpy as np
import pytest
import xxhash
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cclogfs.codecs import codec_from_config, columns, raw_size, shapes, utf8_size
from cclogfs.codecs.columnar import ColumnarCodec
from cclogfs.codecs.columnar_format import FORMAT_VERSIONS, HEADER, LATEST_VERSION, ColumnKind
from cclogfs.errors import CodecError

GOLDEN = Path(__file__).parent.parent / "golden" / "columnar"
CODEC = ColumnarCodec()

# Every test here runs on both row paths (tests/conftest.py: row_path).
pytestmark = pytest.mark.usefixtures("row_path")


def as_text(texts: list[bytes | str]) -> list[str]:
    """Texts as the codec boundary carries them (stray bytes as surrogate escapes)."""
    return [t if isinstance(t, str) else t.decode("utf-8", "surrogateescape") for t in texts]


def round_trip(texts: list[bytes], stamps: list[int] | None = None, codec=CODEC) -> bytes:
    stamps = list(range(len(texts))) if stamps is None else stamps
    texts = as_text(texts)
    data = codec.encode(stamps, texts)
    assert codec.decode(data, count=len(texts), raw_len=raw_size(stamps, texts)) == (stamps, texts)
    return data


# --- any JSON text, in any spelling ------------------------------------------------------

json_leaves = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(1 << 70), max_value=1 << 70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12)
)
json_values = st.recursive(
    json_leaves,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=4),
    max_leaves=20,
)
dump_options = st.fixed_dictionaries(
    {
        "ensure_ascii": st.booleans(),
        "separators": st.sampled_from([None, (",", ":"), (" ,", " : ")]),
        "indent": st.sampled_from([None, 1, "\t"]),
        "sort_keys": st.booleans(),
    }
)
# Spellings json.dumps never writes but JSON (or Python's json) accepts.
odd_texts = st.sampled_from(
    [
        b"1.0", b"1.00", b"1e0", b"1E+0", b"-0.0", b"-0", b"0.1e-7", b"NaN", b"-Infinity",
        b'{"a": 1, "a": 2}', b'{"a":1.50}', b'{ "a" :\r\n 1 }', b'"\\u00e9"', b'"\xc3\xa9"',
        b'"\\ud83d\\ude00"', b"[1,2,3,]", b"123456789012345678901234567890", b"", b" ",
        b'{"x": nan}', b"\xff\xfe not utf-8", b"[[[[[[[[[[]]]]]]]]]]", b'"a\\"b"', b"tru",
        b'{"k": "%s %d %%"}', b'{"%": 1.5}',
    ]
)


@st.composite
def json_texts(draw) -> bytes:
    value = draw(json_values)
    return json.dumps(value, **draw(dump_options)).encode()


any_text = json_texts() | odd_texts | st.binary(max_size=40) | st.text(max_size=40).map(str.encode)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(json_texts())
def test_any_json_document_round_trips(text):
    round_trip([text])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_any_list_of_texts_round_trips(data):
    texts = data.draw(st.lists(any_text, max_size=12))
    i64 = st.integers(min_value=-(1 << 63), max_value=(1 << 63) - 1)
    stamps = data.draw(st.lists(i64, min_size=len(texts), max_size=len(texts)))
    round_trip(texts, stamps)


@st.composite
def one_shape_windows(draw) -> list[bytes]:
    """Many messages of one shape whose values vary: exercises the typed columns."""
    template = draw(st.dictionaries(st.text(max_size=4), json_leaves, min_size=1, max_size=6))
    keys = list(template)
    rows = draw(st.lists(st.lists(json_leaves, min_size=len(keys), max_size=len(keys)), min_size=2, max_size=20))
    return [json.dumps(dict(zip(keys, row))).encode() for row in rows]


@settings(max_examples=100, deadline=None)
@given(one_shape_windows(), st.sampled_from(FORMAT_VERSIONS))
def test_varying_columns_round_trip(texts, version):
    round_trip(texts, codec=ColumnarCodec(version=version))


I64 = [-(1 << 63), (1 << 63) - 1]


@pytest.mark.parametrize(
    "stamps",
    [[], [5], [7, 7, 7], I64, I64[::-1], [0, I64[0]], [I64[0], 0, I64[0]], [0, 1000, 3000, 2000], [I64[1], 0, 2]],
)
def test_packed_stamps_round_trip_at_the_extremes(stamps):
    texts = [b"{}"] * len(stamps)
    for version in FORMAT_VERSIONS:
        round_trip(texts, stamps, codec=ColumnarCodec(version=version))


def test_packed_ints_drop_the_common_step():
    """Log times in microseconds with jitter, header stamps 36 ms apart: v2 drops the zeros."""
    jitter = random.Random(1)
    stamps = [1_700_000_000_000_000_000 + 36_000_000 * i + 1000 * jitter.randrange(1000) for i in range(200)]
    texts = [json.dumps({"sec": 36 * i // 1000, "nanosec": 36_000_000 * i % 10**9}).encode() for i in range(200)]
    v1 = round_trip(texts, stamps, codec=ColumnarCodec(version=1))
    v2 = round_trip(texts, stamps, codec=ColumnarCodec(version=2))
    assert len(v2) < len(v1) * 0.8


def test_base64_with_nonzero_padding_bits_stays_exact():
    """"QR==" decodes to the byte of "QQ==": such a column must not be stored as bytes."""
    blob = base64.b64encode(bytes(range(70))).decode()
    texts = [json.dumps({"b": blob[:-3] + "R==" if i % 2 else blob}).encode() for i in range(10)]
    assert base64.b64encode(base64.b64decode(texts[1][7:-2])) != texts[1][7:-2]
    round_trip(texts)


@pytest.mark.parametrize("version", FORMAT_VERSIONS)
def test_typed_columns_cover_every_kind(version):
    floats = [1.5 + i / 7 for i in range(50)]
    texts = [
        json.dumps(
            {
                "i": i * 1000,
                "f": floats[i],
                "b": i % 3 == 0,
                "s": f"frame {i}",
                "raw": base64.b64encode(bytes(range(i, i + 80))).decode(),
                "q": {"x": 0.0, "y": 0.0, "z": math.sin(i / 9), "w": math.cos(i / 9)},
                "nan": [math.nan, math.inf, -math.inf][i % 3],
                "big": 1 << 70 if i % 2 else -1,
                "null": None if i % 2 else 0,
            }
        ).encode()
        for i in range(50)
    ]
    data = round_trip(texts, codec=ColumnarCodec(version=version))
    assert len(data) < len(b"".join(texts)) // 2


# Spellings a float or int column may hold, several the decoder would never write back.
NUMBER_SPELLINGS = [
    "0.0", "-0.0", "0", "-0", "1.5", "1.50", "1e16", "1e+16", "1E16", "10000000000000000.0",
    "0.1", "0.10000000000000001", "NaN", "Infinity", "-Infinity", "nan", "1_0", "7", "007",
    "-2.8019166340612314", "9223372036854775807", "9223372036854775808", "0.00001", "1e-05",
]


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(NUMBER_SPELLINGS), st.sampled_from(NUMBER_SPELLINGS[:6])),
                min_size=17))
def test_repeated_tokens_in_any_spelling_round_trip(rows):
    """Columns with repeats are checked token by distinct token: every spelling stays exact."""
    texts = [f'{{"a": {a}, "b": [{b}]}}'.encode() for a, b in rows[:60]]
    for version in FORMAT_VERSIONS:
        round_trip(texts, codec=ColumnarCodec(version=version))


def test_float_parsing_without_simdjson_writes_the_same_bytes(monkeypatch):
    steps = random.Random(3)
    xs = [0.0]
    for _ in range(199):
        xs.append(xs[-1] + steps.uniform(0, 0.01))
    texts = [json.dumps({"x": x, "v": steps.choice([0.0, 0.1, -0.25]), "n": math.nan}) for x in xs]
    fast = ColumnarCodec().encode(list(range(200)), texts)
    monkeypatch.setattr(columns, "simdjson", None)
    assert ColumnarCodec().encode(list(range(200)), texts) == fast
    round_trip(texts, codec=ColumnarCodec())


def test_number_columns_with_commas_or_odd_ints_stay_text():
    """Float tokens are compared as one list repr; a comma inside a token must not pass."""
    assert columns.classify(("1.5, 2.5", "3.5"))[0] is ColumnKind.TEXT
    assert columns.classify(("1.5", "2.5, 3.5"))[0] is ColumnKind.TEXT
    assert columns.classify(("+5", "6"))[0] is ColumnKind.TEXT
    assert columns.classify(("5", "1.5"))[0] is ColumnKind.TEXT
    assert columns.classify(("-5", "6"))[0] is ColumnKind.INT
    assert columns.classify(("1.5", "-0.0"))[0] is ColumnKind.FLOAT


def test_float_delta_order_follows_the_column():
    t = np.arange(200) / 27.0
    smooth = np.sin(t) * 3.0  # a position: second or third differences are smallest
    steps = np.repeat(np.random.default_rng(5).normal(size=20), 10)  # a velocity: first differences
    orders, planes = columns.float_deltas(np.stack([smooth, steps]).view("<i8"))
    assert orders[0] in (2, 3) and orders[1] == 1
    assert all(len(p) == 8 * 200 for p in planes)


def test_unknown_float_delta_order_raises():
    for order in (0, 4, 255):
        with pytest.raises(CodecError, match=f"delta order {order}"):
            columns.read_column(ColumnKind.FLOAT_DELTA, columns.Reader(bytes([order]) + bytes(80)), 10, [])


def test_column_kind_of_a_later_version_raises():
    """A v2 payload holding a v3 kind (INT_OFFSET) is corrupt, not silently decoded."""
    texts = [json.dumps({"i": 7 * i}) for i in range(10)]
    stamps = [0] * 10
    data = ColumnarCodec(version=2).encode(stamps, texts)
    body = bytearray(zstandard.ZstdDecompressor().decompress(data[HEADER.size :]))
    kind_at = 4 + 2 * 10 + 17 + 8 + 4 * 2 + 4 + len('{"i": }')  # see docs/CODEC_COLUMNAR.md
    assert body[kind_at] == ColumnKind.INT_PACKED
    body[kind_at] = ColumnKind.INT_OFFSET
    frame = zstandard.ZstdCompressor().compress(bytes(body))
    bad = HEADER.pack(2, len(body), xxhash.xxh32_intdigest(frame)) + frame
    with pytest.raises(CodecError, match="not one of format version 2"):
        ColumnarCodec().decode(bad, count=10, raw_len=raw_size(stamps, texts))


@pytest.mark.parametrize("version", FORMAT_VERSIONS)
def test_python_spellings_of_nan_and_inf_stay_exact(version):
    """repr writes nan and inf, the decoder NaN and Infinity: such a column is not FLOAT."""
    for odd in ("nan", "inf", "-inf"):
        texts = [f'{{"a": {odd if i == 0 else i / 3}}}'.encode() for i in range(10)]
        round_trip(texts, codec=ColumnarCodec(version=version))


def test_literals_of_equal_length_but_other_text_are_not_skipped_over():
    """The skipping matcher steps over literals by length: other keys of that length must
    still split the window (checked by rebuilding the texts), never be taken as the shape."""
    texts = [json.dumps({"a": i / 7, "bc"[i % 3 == 0]: i}).encode() for i in range(60)]
    round_trip(texts)
    round_trip([b"{}", b"[]", b"{}"] * 10)  # no values at all: the skipper only checks lengths
    literals, kinds = ('{"a": ', ', "b": ', "}"), (False, False)
    skipper = shapes._skipper(literals, kinds)
    good, other = '{"a": 0.5, "b": 1}', '{"a": 0.5, "c": 1}'
    assert skipper.fullmatch(other) is not None  # the skipper alone cannot tell them apart
    rows = [("0.5", "1"), ("0.5", "1")]
    assert shapes._rebuilds(literals, rows, [good, good])
    assert not shapes._rebuilds(literals, rows, [good, other])
    shape = (literals, shapes._regex(literals, kinds), skipper, kinds)
    assert shapes._rows(shape, [good, other, "x", good]) == [("0.5", "1"), None, None, ("0.5", "1")]


def test_mixed_shapes_in_one_window():
    texts = [json.dumps({"a": list(range(i % 4)), **({"extra": i} if i % 5 == 0 else {})}).encode() for i in range(40)]
    round_trip(texts + [b"not json at all", b"\x80\x81"])


def test_empty_window():
    round_trip([])


# --- config and golden payloads ----------------------------------------------------------


def test_config_round_trips_through_registry():
    codec = codec_from_config({"id": "columnar", "version": 1, "level": 9})
    assert codec.get_config() == {"id": "columnar", "version": 1, "level": 9}
    assert codec_from_config("columnar").get_config()["version"] == LATEST_VERSION == 4
    with pytest.raises(CodecError, match="version 99 is unknown"):
        codec_from_config({"id": "columnar", "version": 99})


def _golden_cases() -> list[Path]:
    return sorted(p for p in GOLDEN.iterdir() if p.is_dir())


def _load_inputs(case: Path) -> tuple[list[int], list[str]]:
    rows = [json.loads(line) for line in (case / "inputs.jsonl").read_text().splitlines()]
    return [r["stamp_ns"] for r in rows], as_text([base64.b64decode(r["text_b64"]) for r in rows])


def test_every_format_version_has_golden_payloads():
    versions = {json.loads((case / "config.json").read_text())["version"] for case in _golden_cases()}
    assert versions == set(FORMAT_VERSIONS)


def test_golden_payloads_decode():
    cases = _golden_cases()
    assert cases, f"no golden cases under {GOLDEN}"
    for case in cases:
        stamps, texts = _load_inputs(case)
        codec = codec_from_config(json.loads((case / "config.json").read_text()))
        encoded = (case / "encoded.bin").read_bytes()
        got = codec.decode(encoded, count=len(texts), raw_len=raw_size(stamps, texts))
        assert got == (stamps, texts), case.name


# --- real data ----------------------------------------------------------------------------


def _topics(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    from rosbags.highlevel import AnyReader

    from cclogfs.jsontext.ros import message_to_json

    by_topic: dict[str, list[tuple[int, bytes]]] = {}
    with AnyReader([path]) as reader:
        for con, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, con.msgtype)
            by_topic.setdefault(con.topic, []).append((stamp, message_to_json(msg).encode()))
    return by_topic


@pytest.mark.parametrize("name", ["nav2_turtlebot.mcap", "tf_example.bag", "tf_example"])
def test_every_real_message_round_trips(shared_data, name):
    for topic, messages in _topics(shared_data(name)).items():
        for start in range(0, len(messages), 200):
            window = messages[start : start + 200]
            stamps, texts = [s for s, _ in window], [t for _, t in window]
            data = round_trip(texts, stamps)
            if len(window) == 200:
                assert len(data) < sum(map(len, texts)) // 10, topic


# --- corruption -------------------------------------------------------------------------

WINDOW_STAMPS = [1_000_000 * i for i in range(60)]
WINDOW_TEXTS = [
    json.dumps({"i": i, "x": i / 3, "s": "abc"[i % 3], "b": i % 2 == 0, "d": [i] * (i % 3)})
    for i in range(60)
] + as_text([b"\xffraw", b"{}"])
WINDOW_STAMPS.extend([7, 8])


def _decode(data: bytes):
    return CODEC.decode(data, count=len(WINDOW_TEXTS), raw_len=raw_size(WINDOW_STAMPS, WINDOW_TEXTS))


def _body(data: bytes) -> bytearray:
    return bytearray(zstandard.ZstdDecompressor().decompress(data[HEADER.size :]))


def _repack(body: bytes, body_len: int | None = None) -> bytes:
    frame = zstandard.ZstdCompressor().compress(bytes(body))
    body_len = len(body) if body_len is None else body_len
    return HEADER.pack(LATEST_VERSION, body_len, xxhash.xxh32_intdigest(frame)) + frame


GOOD = CODEC.encode(WINDOW_STAMPS, WINDOW_TEXTS)


def test_truncated_payload_raises():
    for cut in range(0, len(GOOD), 7):
        with pytest.raises(CodecError):
            _decode(GOOD[:cut])


def test_flipped_bytes_raise():
    for pos in range(len(GOOD)):
        bad = bytearray(GOOD)
        bad[pos] ^= 0x40
        with pytest.raises(CodecError):
            _decode(bytes(bad))


def test_wrong_raw_len_raises():
    with pytest.raises(CodecError):
        CODEC.decode(GOOD, count=len(WINDOW_TEXTS), raw_len=raw_size(WINDOW_STAMPS, WINDOW_TEXTS) - 1)
    with pytest.raises(CodecError):
        CODEC.decode(GOOD, count=len(WINDOW_TEXTS) + 1, raw_len=raw_size(WINDOW_STAMPS, WINDOW_TEXTS))


def test_forged_body_length_in_header_raises():
    bad = _repack(_body(GOOD), body_len=0xFFFFFFFF)
    with pytest.raises(CodecError, match="claims a"):
        _decode(bad)


def test_forged_lengths_inside_body_raise():
    """Any u32 of the body (with a valid checksum) forged huge: CodecError, never MemoryError.

    Where the forged bytes land in column data rather than a length, the payload is
    legal and decodes to other values; the decoder still keeps the window's framing.
    """
    body = _body(GOOD)
    assert _decode(_repack(body)) == (WINDOW_STAMPS, WINDOW_TEXTS)
    for pos in range(0, len(body) - 3):
        for value in (0xFFFFFFFF, 0x7FFFFFFF, 1 << 20):
            bad = bytearray(body)
            bad[pos : pos + 4] = struct.pack("<I", value)
            try:
                got = _decode(_repack(bad))
            except CodecError:
                continue
            assert len(got[1]) == len(WINDOW_TEXTS)
            assert utf8_size(got[1]) == utf8_size(WINDOW_TEXTS)


def test_forged_zero_width_columns_cannot_amplify_memory():
    # 2,000 integer columns of width 0 cost a few bytes each but would render 200 twenty-digit
    # numbers apiece: the decoder must stop at the window size the header states (found by
    # review: before, a ~50-byte payload held hundreds of MB before failing).
    import struct
    import tracemalloc

    import numpy as np
    import xxhash
    import zstandard

    from cclogfs.errors import CodecError

    count, k = 200, 2000
    raw_len = 4 + 12 * count + 60_000
    body = bytearray(struct.pack("<I", 1)) + np.zeros(count, "<u2").tobytes()
    body += struct.pack("<qQqB", 0, 0, 0, 0)  # stamps: offset packing, width 0
    body += struct.pack("<II", count, k) + np.zeros(k + 1, "<u4").tobytes() + struct.pack("<I", 0)
    body += bytes([10]) * k  # INT_OFFSET columns
    for _ in range(k):
        body += struct.pack("<qQqB", -(2**63 - 1), 0, 0, 0)
    frame = zstandard.ZstdCompressor().compress(bytes(body))
    payload = struct.pack("<BII", 3, len(body), xxhash.xxh32_intdigest(frame)) + frame
    tracemalloc.start()
    try:
        with pytest.raises(CodecError, match="renders beyond the window size"):
            codec_from_config("columnar").decode(payload, count=count, raw_len=raw_len)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20, f"decoding allocated {peak} bytes"
