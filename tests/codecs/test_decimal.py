"""DECIMAL columns (columnar format version 4): fixed-point tokens stored as integers."""

from __future__ import annotations

import base64
import json
import re
import struct
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
import xxhash
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cclogfs.codecs import columns, raw_size
from cclogfs.codecs.columnar import ColumnarCodec
from cclogfs.codecs.columnar_format import FORMAT_VERSIONS, GROUP_HEADER, HEADER, ColumnKind
from cclogfs.errors import CodecError

V4 = ColumnarCodec(version=4)
GOLDEN = Path(__file__).parent.parent / "golden" / "columnar"
I64_MIN, I64_MAX = -(1 << 63), (1 << 63) - 1


def fixed(m: int, d: int) -> str:
    """m with its point d digits from the right, by Decimal: an oracle apart from the codec."""
    return format(Decimal(m).scaleb(-d), "f")


def round_trip(texts: list[str], codec=V4) -> bytes:
    stamps = [1_000_000 * i for i in range(len(texts))]
    data = codec.encode(stamps, texts)
    assert codec.decode(data, count=len(texts), raw_len=raw_size(stamps, texts)) == (stamps, texts)
    return data


def body_of(data: bytes) -> bytearray:
    return bytearray(zstandard.ZstdDecompressor().decompress(data[HEADER.size :]))


def repack(body: bytes, version: int = 4) -> bytes:
    frame = zstandard.ZstdCompressor().compress(bytes(body))
    return HEADER.pack(version, len(body), xxhash.xxh32_intdigest(frame)) + frame


def written_kinds(data: bytes, count: int) -> tuple[list[int], int]:
    """(column kinds, body offset of the first column) of the first group, read from the bytes."""
    reader = columns.Reader(body_of(data))
    assert reader.u32("groups") >= 1
    reader.ints("H", count, "ids")
    columns.read_packed(reader, count, "stamps", offset=True)
    _, slots = GROUP_HEADER.unpack(reader.take(GROUP_HEADER.size, "group header"))
    columns._read_blob(reader, slots + 1, "literals")
    kinds = reader.take(slots, "kinds").tolist()
    return kinds, reader.pos


def first_group_rows(data: bytes, count: int) -> int:
    reader = columns.Reader(body_of(data))
    reader.u32("groups")
    reader.ints("H", count, "ids")
    columns.read_packed(reader, count, "stamps", offset=True)
    rows, _ = GROUP_HEADER.unpack(reader.take(GROUP_HEADER.size, "group header"))
    return rows


def window(columns_of_tokens: list[list[str]]) -> list[str]:
    """One JSON text per row, key c<j> holding token j of that row verbatim."""
    rows = zip(*columns_of_tokens)
    return [("{" + ", ".join(f'"c{j}": {t}' for j, t in enumerate(row)) + "}")
            for row in rows]


# --- the encoder's choice -----------------------------------------------------------------


@pytest.mark.parametrize("d", [1, 3, 6, 18])
def test_all_fixed_point_column_is_written_as_decimal(d):
    """Fails if the encoder stops choosing DECIMAL: the kind byte written is checked."""
    n = 40
    tokens = [
        [fixed(1000 * i - 7000, d) for i in range(n)],  # crosses zero, negative values
        [fixed((i * 37) % 11 - 5, d) for i in range(n)],  # noisy, small
        [fixed(0 if i % 4 else 3, d) for i in range(n)],  # mostly zero: "0.000", never "-0.000"
    ]
    texts = window(tokens)
    kinds, _ = written_kinds(round_trip(texts), n)
    assert kinds == [ColumnKind.DECIMAL] * 3
    v3_kinds, _ = written_kinds(round_trip(texts, ColumnarCodec(version=3)), n)
    assert ColumnKind.DECIMAL not in v3_kinds  # a version 3 payload never holds kind 11


def test_decimal_beats_float_bits_on_rounded_values():
    n = 200
    tokens = [[fixed(int(1000 * np.sin(i / 30)), 3) for i in range(n)]]
    v3, v4 = round_trip(window(tokens), ColumnarCodec(version=3)), round_trip(window(tokens))
    assert len(v4) < len(v3)


@pytest.mark.parametrize(
    "odd",
    ["-0.000", "1e-3", ".5", "1.50", "01.500", "+1.500", "9223372036854775.808",
     "1000000000000.000", "NaN", "7"],
)
def test_a_token_that_does_not_render_back_keeps_the_column_out_of_decimal(odd):
    n = 30
    tokens = [fixed(250 * i, 3) for i in range(n)]
    tokens[n // 2] = odd
    texts = window([tokens])
    data = round_trip(texts)
    kinds, _ = written_kinds(data, n)
    assert kinds != [ColumnKind.DECIMAL]
    assert columns.classify(tuple(tokens), decimal=True)[0] is not ColumnKind.DECIMAL


def test_spellings_int_accepts_but_json_does_not_stay_out_of_decimal():
    """int() reads "1_0", " 1" and other scripts' digits; only the rendering check refuses them."""
    for odd in ("1_0.500", " 1.500", "1.500 ", "\u0661.500", "1.5\u0660\u0660"):
        assert columns.classify(("2.000", odd, "3.000"), decimal=True)[0] is not ColumnKind.DECIMAL


def test_rendering_of_the_edges():
    got = columns._render_decimals([0, -5, -1500, 12000, 1], 3)
    assert got == ["0.000", "-0.005", "-1.500", "12.000", "0.001"]
    got = columns._render_decimals([I64_MIN, I64_MAX], 18)
    assert got == [fixed(I64_MIN, 18), fixed(I64_MAX, 18)]


# --- round trips --------------------------------------------------------------------------

# Values m of a column's fixed-point tokens: small, near the encoder's 10^15 limit (either
# side), beyond i64, or any mix of those.
small = st.integers(min_value=-5000, max_value=5000)
near_limit = st.integers(10**15 - 3, 10**15 + 3).map(lambda m: m * (-1) ** (m % 2))
huge = st.integers(min_value=-(1 << 70), max_value=1 << 70)
m_regimes = st.sampled_from([small, small, near_limit, huge, small | near_limit | huge])
# Number tokens the column may also hold that are not fixed-point with its d.
other_tokens = st.sampled_from(
    ["-0.000", "-0.0", "0.0", "1e-3", "1E3", ".5", "1.50", "1.500", "12", "-7", "0.1", "NaN",
     "-Infinity", "1.0000000000000000000", "123456789012345678901234567890.5"]
)


@st.composite
def fixed_point_columns(draw) -> list[list[str]]:
    n = draw(st.integers(min_value=2, max_value=40))
    out = []
    for _ in range(draw(st.integers(min_value=1, max_value=4))):
        d = draw(st.integers(min_value=1, max_value=18))
        m_values = draw(m_regimes)
        column = [fixed(m, d) for m in draw(st.lists(m_values, min_size=n, max_size=n))]
        for i in draw(st.lists(st.integers(0, n - 1), max_size=2)):  # often none: all fixed
            column[i] = draw(other_tokens)
        out.append(column)
    return out


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fixed_point_columns())
def test_fixed_point_windows_round_trip_exactly(cols):
    texts = window(cols)
    for version in FORMAT_VERSIONS:
        round_trip(texts, ColumnarCodec(version=version))
    # A fresh codec: a shared one may reuse the last window's shape (its bytes may depend on
    # the window before, see shapes.ShapeMatcher), which folds other values into literals.
    data = ColumnarCodec(version=4).encode(list(range(len(texts))), texts)
    kinds, _ = written_kinds(data, len(texts))
    # The shape is found from probes: a value the probes saw constant goes into the
    # literals and the texts where it differs into another group. Kinds are compared only
    # when one group holds the whole window.
    if all(len(set(column)) > 1 for column in cols) and first_group_rows(data, len(texts)) == len(texts):  # else a column may be a literal
        assert len(kinds) == len(cols)
        for column, kind in zip(cols, kinds):
            assert (kind == ColumnKind.DECIMAL) == expect_decimal(column), column


def expect_decimal(column: list[str]) -> bool:
    """Whether the encoder should write DECIMAL, decided apart from the codec's code."""
    digits = set()
    for t in column:
        match = re.fullmatch(r"-?(?:0|[1-9][0-9]*)\.([0-9]+)", t)
        if match is None:
            return False
        m = int(t.replace(".", ""))
        if abs(m) >= 10**15 or (m == 0 and t[0] == "-"):
            return False
        digits.add(len(match.group(1)))
    return len(digits) == 1 and digits.pop() <= 18


@settings(max_examples=150, deadline=None)
@given(
    st.integers(min_value=1, max_value=18),
    st.lists(st.integers(I64_MIN, I64_MAX) | st.sampled_from([0, -1, 1, I64_MIN, I64_MAX]),
             min_size=1, max_size=40),
)
def test_any_i64_column_renders_back_through_every_order(d, ms):
    """The format holds any i64 m (the encoder writes only |m| < 10^15); every order wraps back."""
    values = np.array(ms, dtype=np.int64)
    expected = [fixed(m, d) for m in ms]
    for order in (None, 1, 2, 3):
        out = bytearray()
        if order is None:
            columns.write_decimal(d, values, out)
        else:
            out += bytes((d, order))
            columns.write_packed(columns._decimal_words(values, order), out, offset=True)
        reader = columns.Reader(bytes(out))
        assert columns.read_decimal(reader, len(ms)) == expected
        assert reader.pos == len(out)


def test_order_follows_the_column():
    t = np.arange(200)
    smooth = (np.sin(t / 40) * 1e6).astype(np.int64)  # a position: higher differences are smaller
    noisy = np.random.default_rng(4).integers(-50, 50, size=200)  # a velocity: first order
    orders = []
    for values in (smooth, noisy):
        out = bytearray()
        columns.write_decimal(4, values, out)
        orders.append(out[1])
    assert orders[0] in (2, 3) and orders[1] == 1


# --- golden payloads ----------------------------------------------------------------------


@pytest.mark.parametrize("case", ["v4-decimal-kinds", "v4-aged-odom"])
def test_golden_windows_hold_decimal_columns(case):
    """The v4 goldens with fixed-point values pin DECIMAL's layout, not only FLOAT's."""
    rows = [json.loads(line) for line in (GOLDEN / case / "inputs.jsonl").read_text().splitlines()]
    texts = [base64.b64decode(r["text_b64"]).decode() for r in rows]
    stamps = [r["stamp_ns"] for r in rows]
    data = (GOLDEN / case / "encoded.bin").read_bytes()
    assert V4.decode(data, count=len(texts), raw_len=raw_size(stamps, texts)) == (stamps, texts)
    kinds, _ = written_kinds(data, len(texts))
    assert kinds.count(ColumnKind.DECIMAL) >= 4


# --- corruption ---------------------------------------------------------------------------

N = 30
TEXTS = window([[fixed(5 * i - 40, 3) for i in range(N)]])
GOOD = V4.encode(list(range(N)), TEXTS)


def decode(data: bytes):
    return V4.decode(data, count=N, raw_len=raw_size(list(range(N)), TEXTS))


def test_the_corruption_window_holds_one_decimal_column():
    kinds, at = written_kinds(GOOD, N)
    assert kinds == [ColumnKind.DECIMAL]
    body = body_of(GOOD)
    assert body[at] == 3 and body[at + 1] in (1, 2, 3)
    assert decode(repack(body)) == (list(range(N)), TEXTS)


@pytest.mark.parametrize("d", [0, 19, 255])
def test_digits_outside_1_to_18_raise(d):
    _, at = written_kinds(GOOD, N)
    body = body_of(GOOD)
    body[at] = d
    with pytest.raises(CodecError, match=f"decimal column names {d} digits"):
        decode(repack(body))


@pytest.mark.parametrize("order", [0, 4, 255])
def test_unknown_decimal_delta_order_raises(order):
    _, at = written_kinds(GOOD, N)
    body = body_of(GOOD)
    body[at + 1] = order
    with pytest.raises(CodecError, match=f"delta order {order}"):
        decode(repack(body))


def test_wide_or_truncated_decimal_column_raises():
    _, at = written_kinds(GOOD, N)
    body = body_of(GOOD)
    wide = bytearray(body)
    wide[at + 2 + 24] = 9  # offset(n) width byte: at most 8
    with pytest.raises(CodecError, match="decimal column"):
        decode(repack(wide))
    for cut in range(at, len(body)):
        with pytest.raises(CodecError):
            decode(repack(body[:cut]))


def test_decimal_kind_in_a_version_3_payload_raises():
    with pytest.raises(CodecError, match="not one of format version 3"):
        decode(repack(body_of(GOOD), version=3))


def test_flipped_bytes_of_a_decimal_payload_raise():
    for pos in range(len(GOOD)):
        bad = bytearray(GOOD)
        bad[pos] ^= 0x10
        with pytest.raises(CodecError):
            decode(bytes(bad))


def test_forged_column_bytes_never_change_the_window_size():
    """Any byte of the DECIMAL column forged (valid checksum): CodecError, or other digits of
    the same lengths; never more or less text than the window holds."""
    _, at = written_kinds(GOOD, N)
    body = body_of(GOOD)
    for pos in range(at, len(body)):
        for value in (0x00, 0x01, 0x7F, 0xFF):
            bad = bytearray(body)
            bad[pos] = value
            try:
                got = decode(repack(bad))
            except CodecError:
                continue
            assert sum(map(len, got[1])) == sum(map(len, TEXTS))
    for pos in range(at, len(body) - 3):
        bad = bytearray(body)
        bad[pos : pos + 4] = struct.pack("<I", 0xFFFFFFFF)
        try:
            decode(repack(bad))
        except CodecError:
            pass


# --- real data ----------------------------------------------------------------------------


def test_unrounded_real_data_is_written_as_version_3_wrote_it(shared_data):
    """Why 4 is the default: without rounded values it is version 3 byte for byte (the
    10^15 limit keeps equal-length float reprs, as on /tf, out of DECIMAL)."""
    from rosbags.highlevel import AnyReader

    from cclogfs.jsontext.ros import message_to_json

    by_topic: dict[str, list[tuple[int, bytes]]] = {}
    with AnyReader([shared_data("nav2_turtlebot.mcap")]) as reader:
        for con, stamp, raw in reader.messages():
            text = message_to_json(reader.deserialize(raw, con.msgtype))
            by_topic.setdefault(con.topic, []).append((stamp, text))
    v3 = ColumnarCodec(version=3)
    for topic, messages in by_topic.items():
        for start in range(0, len(messages), 200):
            stamps = [s for s, _ in messages[start : start + 200]]
            texts = [t for _, t in messages[start : start + 200]]
            assert V4.encode(stamps, texts)[1:] == v3.encode(stamps, texts)[1:], (topic, start)
