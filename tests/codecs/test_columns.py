"""cclogfs.codecs.columns: one value slot of a shape, classified, written and read back."""

import base64
import json

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from cclogfs.codecs import columns
from cclogfs.codecs.columnar_format import OFFSET_HEADER, PACKED_HEADER, ColumnKind
from cclogfs.codecs.columns import Reader, classify, read_column, read_packed, write_column, write_packed
from cclogfs.errors import CodecError

B64 = tuple('"' + base64.b64encode(bytes([i]) * 60).decode() + '"' for i in range(3))


def round_trip(tokens, decimal=False):
    kind, values = classify(tokens, decimal=decimal)
    out = bytearray()
    write_column(kind, values, out)
    reader = Reader(bytes(out))
    got, _floats = read_column(kind, reader, len(tokens), [])
    assert reader.pos == len(out)  # the column reads exactly what was written
    return kind, got


@pytest.mark.parametrize(
    "tokens, kind",
    [
        (("7", "7", "7"), ColumnKind.CONST),
        (('"a"', '"bé"', '""'), ColumnKind.TEXT),
        (("1", "-5", "9223372036854775807"), ColumnKind.INT),
        (("0.1", "2.5e-07", "-3.0"), ColumnKind.FLOAT),
        (("true", "false", "true"), ColumnKind.BOOL),
        (B64, ColumnKind.BASE64),
        (("01", "2", "3"), ColumnKind.TEXT),  # not canonical ints: kept as written
        (("1", "9223372036854775808", "0"), ColumnKind.TEXT),  # over i64
        (("1.50", "2.25", "3.00"), ColumnKind.TEXT),  # floats that do not render back
        (("3", "3", "4", "3", "3", "4", "5", "3", "3"), ColumnKind.INT),  # repeats take the dedup path
    ],
)
def test_classify_picks_a_kind_that_reproduces_every_token(tokens, kind):
    got_kind, got = round_trip(tokens)
    assert got_kind is kind
    assert got == (tokens[0] if kind is ColumnKind.CONST else list(tokens))


def test_decimal_only_when_allowed():
    tokens = ("1.50", "2.25", "3.00")
    kind, got = round_trip(tokens, decimal=True)
    assert kind is ColumnKind.DECIMAL and got == list(tokens)


@pytest.mark.parametrize("offset", [False, True])
@pytest.mark.parametrize(
    "values",
    [[5], [0, 36_000, 72_000, 108_001], [-(2**63), 2**63 - 1, 0, -1], [10, 10, 10], []],
)
def test_packed_integers_round_trip(values, offset):
    out = bytearray()
    write_packed(np.array(values, dtype="<i8"), out, offset=offset)
    reader = Reader(bytes(out))
    assert read_packed(reader, len(values), "t", offset=offset) == values
    assert reader.pos == len(out)


def test_a_steady_rate_packs_into_its_header_alone():
    stamps = np.arange(0, 36_000 * 1000, 36_000, dtype="<i8")
    out = bytearray()
    write_packed(stamps, out, offset=True)
    assert len(out) == OFFSET_HEADER.size  # every quotient equals the base: zero-width deltas
    out = bytearray()
    write_packed(stamps, out)
    assert len(out) == PACKED_HEADER.size + len(stamps) - 1  # zigzag(1) = 2: one byte each


def test_reader_refuses_to_read_past_the_end():
    reader = Reader(b"\x01\x02")
    with pytest.raises(CodecError, match="count at body offset 0 needs 4 bytes, 2 are left"):
        reader.u32("count")
    with pytest.raises(CodecError, match="needs -1 bytes"):
        reader.take(-1, "x")


@pytest.mark.parametrize(
    "kind, data, message",
    [
        (ColumnKind.BOOL, b"\x00\x02", "bool column holds a value above 1"),
        (ColumnKind.CONST, b"\x02\x00\x00\x00\xff\xfe", "constant is not UTF-8"),
        (ColumnKind.TEXT, b"\x01\x00\x00\x00\x09\x00\x00\x00ab", "text column at body offset 8 needs 9"),
        (ColumnKind.QUAT_W, bytes(16), "lacks x, y, z"),
        (ColumnKind.FLOAT_DELTA, b"\x07" + bytes(16), "delta order 7"),
        (200, b"", "unknown column kind 200"),
    ],
)
def test_corrupt_columns_are_codec_errors(kind, data, message):
    n = 2 if kind is not ColumnKind.TEXT else 1
    with pytest.raises(CodecError, match=message):
        read_column(kind, Reader(data), n, [])


def test_text_lengths_that_do_not_add_up_are_refused():
    out = bytearray()
    write_column(ColumnKind.TEXT, ('"ab"', '"c"'), out)
    out[0] += 1  # the first token claims one char more
    with pytest.raises(CodecError, match="lengths do not add up"):
        read_column(ColumnKind.TEXT, Reader(bytes(out)), 2, [])


def classify_without_simdjson(tokens):
    saved, columns.simdjson = columns.simdjson, None
    try:
        return classify(tokens)
    finally:
        columns.simdjson = saved


# Spellings that read as an int (or as a number) but are not what str(int) writes.
ODD_INTS = st.sampled_from(["-0", "+5", "007", "1.5", "1e3", "12x", "0x10", "9223372036854775808", "-9223372036854775809",
                            "18446744073709551616", "1" * 30, "-"])  # fmt: skip


@given(st.lists(st.integers(-(2**63), 2**63 - 1), min_size=16, max_size=40), st.lists(st.tuples(st.integers(0, 39), ODD_INTS), max_size=2))
@settings(max_examples=400, deadline=None)
def test_int_columns_read_at_once_get_int_s_verdict(ints, edits):
    """Int columns of 16 tokens or more are read by simdjson and checked by orjson in one
    call each; the kind and values are those of int() token by token (simdjson off)."""
    tokens = [str(i) for i in ints]
    for at, odd in edits:
        tokens[at % len(tokens)] = odd
    tokens = tuple(tokens)
    kind, values = classify(tokens)
    want_kind, want = classify_without_simdjson(tokens)
    assert kind is want_kind
    if kind is ColumnKind.INT:
        assert values.dtype == want.dtype and values.tolist() == want.tolist()
    elif kind is ColumnKind.FLOAT:
        assert values.tobytes() == want.tobytes()
    else:
        assert values == want
    if not edits:
        assert kind in (ColumnKind.INT, ColumnKind.CONST)


def same_verdict(a, b) -> bool:
    """Whether two classify results are the same kind and values, bit for bit."""
    (ka, va), (kb, vb) = a, b
    if ka is not kb:
        return False
    if ka is ColumnKind.DECIMAL:
        return va[0] == vb[0] and va[1].tobytes() == vb[1].tobytes()
    if isinstance(va, np.ndarray):
        return va.dtype == vb.dtype and va.tobytes() == vb.tobytes()
    return list(va) == list(vb) if ka is not ColumnKind.CONST else va == vb


# Number tokens as a number slot holds them: json.dumps floats (NaN, Infinity, exponents),
# ints beyond i64, fixed-point decimals, and spellings that denote a number otherwise.
_FLOAT_TOKENS = st.floats().map(json.dumps) | st.floats(-1e-3, 1e-3).map(json.dumps)
_NUMBER_TOKENS = st.one_of(
    _FLOAT_TOKENS,
    st.integers(-(2**64), 2**64).map(str),
    st.integers(-10**6, 10**6).map(lambda m: f"{m / 1000:.3f}"),
    ODD_INTS,
    st.sampled_from(["true", "false", "null", "1e-5", "0.00001", "-0.0", "0.10", "nan", "inf", "NaN", "1_0"]),
)
_NUMBER_COLUMNS = st.integers(1, 40).flatmap(lambda n: st.one_of(  # from 16 tokens simdjson reads them at once
    st.lists(_FLOAT_TOKENS, min_size=n, max_size=n),
    st.lists(st.integers(-(2**63), 2**63 - 1).map(str), min_size=n, max_size=n),
    st.lists(st.integers(-10**6, 10**6).map(lambda m: f"{m / 1000:.3f}"), min_size=n, max_size=n),
    st.lists(_NUMBER_TOKENS, min_size=1, max_size=6).flatmap(lambda pool: st.lists(st.sampled_from(pool), min_size=n, max_size=n)),
))


# Real /odom floats whose first tokens share their digit count: DECIMAL is ruled out on the joined text.
_ODOM = ["0.849090576171875", "0.837188720703125", "0.8263397216796875", "0.8155975341796875", "0.802703857421875"] * 4


@given(_NUMBER_COLUMNS, st.lists(st.tuples(st.integers(0, 39), _NUMBER_TOKENS), max_size=2), st.booleans())
@settings(max_examples=1500, deadline=None)
@example(_ODOM, [], True)
@example(_ODOM[:16] + ["0.125"] * 4, [], True)
@example([f"{m / 1000:.3f}" for m in range(20)] + ["1.5"], [], True)
def test_a_joined_number_column_gets_the_token_path_s_verdict(tokens, edits, decimal):
    """The encoder classifies a number slot's tokens joined by "," (as the row finder gives
    them): the same kind and values as classify of the tokens, so the same bytes."""
    for at, token in edits:
        tokens[at % len(tokens)] = token
    got = columns.classify_joined(",".join(tokens), len(tokens), decimal)
    assert same_verdict(got, classify(tuple(tokens), decimal)), tokens


# A group's columns as the row finder gives them: a number slot's tokens joined (or its
# one token when constant), a string slot's list of tokens; all of one length n.
def _group_columns(n: int):
    def joined(tokens):
        return tokens[0] if tokens.count(tokens[0]) == n else ",".join(tokens)

    number = st.one_of(
        st.lists(_FLOAT_TOKENS, min_size=n, max_size=n),
        st.lists(st.floats(-1e-3, 1e-3).map(json.dumps), min_size=n, max_size=n),  # many to respell
        st.lists(st.integers(-(2**63), 2**63 - 1).map(str), min_size=n, max_size=n),
        st.lists(st.integers(-10**6, 10**6).map(lambda m: f"{m / 1000:.3f}"), min_size=n, max_size=n),
        st.lists(_NUMBER_TOKENS, min_size=1, max_size=6).flatmap(lambda pool: st.lists(st.sampled_from(pool), min_size=n, max_size=n)),
    ).map(joined)
    strings = st.lists(st.sampled_from(['"a"', '"b"', '"QUJDRA=="']), min_size=n, max_size=n)
    return st.lists(number | strings, min_size=1, max_size=8)


@given(st.sampled_from([1, 5, 15, 16, 17, 40]).flatmap(lambda n: st.tuples(st.just(n), _group_columns(n))), st.booleans())
@settings(max_examples=800, deadline=None)
def test_a_group_s_columns_get_each_column_s_own_verdict(sized, decimal):
    """classify_columns checks a group's number columns of a type together: each column
    gets the kind and values classify_joined (or classify) gives it alone, whatever the
    others hold (a column simdjson refuses, one orjson spells otherwise, a constant)."""
    n, group = sized
    got = columns.classify_columns(group, n, decimal)
    for column, verdict in zip(group, got, strict=True):
        alone = columns.classify(column, decimal) if isinstance(column, list) else columns.classify_joined(column, n, decimal)
        assert same_verdict(verdict, alone), column


def _float_deltas_reference(bits):
    """float_deltas as first written (a level per order, stacked), with the order's cost
    as it is now (frexp's exponents summed, not log2): the optimised numpy path and the
    compiled one (_planes.c) must give the same orders and planes."""
    k, n = bits.shape
    levels = [bits]
    for _ in (1, 2, 3):
        d = levels[-1].copy()
        np.subtract(levels[-1][:, 1:], levels[-1][:, :-1], out=d[:, 1:])
        levels.append(d)
    if n > 3:
        stride = max(1, n // 64)
        sample = np.stack([levels[r][:, 3::stride] for r in (1, 2, 3)])
        cost = np.frexp(np.abs(sample.astype(np.float64)))[1].sum(axis=2)
        orders = [(1, 2, 3)[i] for i in cost.argmin(axis=0).tolist()]
    else:
        orders = [2] * k
    chosen = np.stack([levels[r][j] for j, r in enumerate(orders)])
    z = ((chosen << 1) ^ (chosen >> 63)).view("<u8")
    planes = z.view(np.uint8).reshape(k, n, 8).transpose(0, 2, 1).tobytes()
    return orders, [planes[8 * n * j : 8 * n * (j + 1)] for j in range(k)]


@given(st.integers(1, 6), st.integers(1, 300), st.integers(0, 2**32 - 1), st.booleans())
@settings(max_examples=300, deadline=None)
def test_float_deltas_matches_its_reference(k, n, seed, smooth):
    rng = np.random.default_rng(seed)
    if smooth:
        bits = np.cumsum(rng.normal(size=(k, n)), axis=1).view("<i8")
    else:
        bits = rng.integers(-(2**63), 2**63 - 1, size=(k, n), dtype=np.int64, endpoint=True)
    want_orders, want_planes = _float_deltas_reference(bits)
    compiled = columns._float_planes_c
    for path in {compiled, None}:  # the compiled path where built, and numpy's
        columns._float_planes_c = path
        try:
            orders, planes = columns.float_deltas(bits)
        finally:
            columns._float_planes_c = compiled
        assert orders == want_orders
        assert [bytes(p) for p in planes] == want_planes


def test_a_group_s_number_columns_are_parsed_in_one_call_per_type(monkeypatch):
    """The point of classify_columns: 7 float and 2 int columns of 200 take 2 parses, not 9."""
    pytest.importorskip("simdjson")
    rng = np.random.default_rng(3)
    floats = [",".join(map(repr, np.cumsum(rng.normal(size=200)).tolist())) for _ in range(7)]
    ints = [",".join(map(str, rng.integers(0, 10**9, 200).tolist())) for _ in range(2)]
    calls = []
    parse = columns._parse_joined
    monkeypatch.setattr(columns, "_parse_joined", lambda *a: calls.append(a[2:]) or parse(*a))
    got = columns.classify_columns([*ints, *floats, "0.0"], 200, decimal=True)
    assert [kind for kind, _ in got] == [ColumnKind.INT] * 2 + [ColumnKind.FLOAT] * 7 + [ColumnKind.CONST]
    assert sorted(calls) == [("d",), ("i",)]


@given(st.integers(0, 6), st.integers(0, 40), st.sampled_from(["<f8", "<i8"]), st.integers(0, 2**32 - 1))
@settings(max_examples=300, deadline=None)
def test_orjson_rows_are_each_row_rendered_alone(k, n, dtype, seed):
    from cclogfs.codecs.columns_read import orjson_rows, orjson_text

    rng = np.random.default_rng(seed)
    if dtype == "<f8":
        rows = rng.normal(size=(k, n)) * 10.0 ** rng.integers(-8, 20, size=(k, n))
    else:
        rows = rng.integers(-(2**63), 2**63 - 1, size=(k, n), dtype=np.int64)
    assert orjson_rows(rows) == ([orjson_text(row) for row in rows] if k else [""])
