"""The compiled byte planes (cclogfs/codecs/_planes.c) give exactly the bytes of the numpy
paths of columns.write_packed and columns.float_deltas, and the decoder reads them back."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.codecs import columns
from cclogfs.codecs.columns_read import Reader, read_packed

try:  # as built, whatever the row_path fixture sets in columns later
    from cclogfs.codecs import _planes as COMPILED
except ImportError:
    COMPILED = None
pytestmark = pytest.mark.skipif(COMPILED is None, reason="cclogfs.codecs._planes is not built")

I64_MIN, I64_MAX = -(1 << 63), (1 << 63) - 1
# The values that break packing: extremes (deltas that wrap, a delta of -2^63 that numpy's
# gcd cannot take), steps (stamps in microseconds), a steady rate with jitter, constants.
EDGES = st.sampled_from([0, 1, -1, I64_MIN, I64_MAX, I64_MIN + 1, 1 << 62, -(1 << 62), 1 << 32, 36_000_000])


def wrapped(values: list[int]) -> list[int]:
    """The values modulo 2^64, as i64 (the steps and scales below may overflow)."""
    return [(v - I64_MIN) % (1 << 64) + I64_MIN for v in values]


WORDS = st.one_of(
    st.lists(st.integers(I64_MIN, I64_MAX) | EDGES, max_size=40),
    st.builds(lambda first, step, jitter: [first + i * step + j for i, j in enumerate(jitter)],
              st.integers(-(1 << 40), 1 << 40), st.integers(-(1 << 20), 1 << 20),
              st.lists(st.integers(-5, 5), min_size=1, max_size=300)),  # fmt: skip
    st.builds(lambda v, n: [v] * n, st.integers(I64_MIN, I64_MAX) | EDGES, st.integers(1, 30)),
    st.builds(lambda scale, xs: [x * scale for x in xs], st.sampled_from([1000, 1 << 62, 3]),
              st.lists(st.integers(-2, 2), min_size=1, max_size=30)),  # fmt: skip
).map(wrapped)


def python_path(fn, *args):
    saved = columns._pack_ints_c, columns._float_planes_c
    columns._pack_ints_c = columns._float_planes_c = None
    try:
        return fn(*args)
    finally:
        columns._pack_ints_c, columns._float_planes_c = saved


def packed(words: np.ndarray, offset: bool) -> bytes:
    out = bytearray()
    columns.write_packed(words, out, offset=offset)
    return bytes(out)


@settings(max_examples=1000)
@given(WORDS, st.booleans())
def test_packed_ints_are_the_numpy_bytes(values, offset):
    words = np.array(values, dtype="<i8")
    compiled = COMPILED.pack_ints(words, offset) if len(words) else b""
    assert compiled == python_path(packed, words, offset)
    assert packed(words, offset) == compiled
    assert read_packed(Reader(compiled), len(values), "test", offset=offset) == values


def test_packed_ints_take_any_array_view():
    words = np.arange(0, 4000, 7, dtype="<i8")[::3]  # not contiguous: write_packed copies it
    assert packed(words, True) == python_path(packed, words, True)
    assert packed(words.astype("<i4"), False) == python_path(packed, words, False)


FLOAT_BITS = st.floats(allow_nan=False, width=64).map(lambda f: int(np.float64(f).view("<i8")))
# k >= 1 rows of n >= 1 values: the encoder calls float_deltas for a group's float columns.
ROWS = st.one_of(
    st.lists(st.lists(st.integers(I64_MIN, I64_MAX) | EDGES | FLOAT_BITS, min_size=5, max_size=5), min_size=1, max_size=4),
    st.builds(lambda k, n, xs: [[xs[(i * 7 + j) % len(xs)] for j in range(n)] for i in range(k)],
              st.integers(1, 5), st.integers(1, 300), st.lists(FLOAT_BITS | EDGES, min_size=1, max_size=50)),  # fmt: skip
    # smooth series (second and third order win) and noisy steps (first order wins)
    st.builds(lambda k, n, a, b: [[int(np.float64(a * i * i + b * (i * 37 % 11) + r).view("<i8")) for i in range(n)] for r in range(k)],
              st.integers(1, 7), st.integers(1, 250), st.floats(-1, 1), st.floats(-1e-3, 1e-3)),  # fmt: skip
)


@settings(max_examples=1000)
@given(ROWS)
def test_float_planes_are_the_numpy_bytes(rows):
    bits = np.array(rows, dtype="<i8")
    orders, planes = columns.float_deltas(bits)
    py_orders, py_planes = python_path(columns.float_deltas, bits)
    assert orders == py_orders
    assert [bytes(p) for p in planes] == [bytes(p) for p in py_planes]
    assert all(order in (1, 2, 3) for order in orders)


def test_float_planes_pick_the_order_a_series_needs():
    i = np.arange(200, dtype=np.float64)
    smooth = 0.5 + 1e-3 * i * i  # quadratic: its second differences are nearly constant
    noisy = np.random.default_rng(1).normal(size=200)  # a velocity: first differences are smallest
    orders, _ = columns.float_deltas(np.array([smooth, noisy]).view("<i8"))
    assert orders == python_path(columns.float_deltas, np.array([smooth, noisy]).view("<i8"))[0]
    assert orders[0] in (2, 3) and orders[1] == 1


def test_misfit_arguments_raise():
    with pytest.raises(ValueError, match="multiple of 8"):
        COMPILED.pack_ints(b"1234567", True)
    with pytest.raises(ValueError, match="k \\* n"):
        COMPILED.float_planes(np.zeros(6, dtype="<i8"), 2, 4)
    with pytest.raises(ValueError, match="k >= 0"):
        COMPILED.float_planes(np.zeros(6, dtype="<i8"), -2, -3)
    with pytest.raises(TypeError):
        COMPILED.pack_ints([1, 2, 3], True)
    with pytest.raises(ValueError, match="not C-contiguous"):
        COMPILED.pack_ints(np.zeros((4, 4), dtype="<i8")[:, 1], True)
    with pytest.raises(ValueError, match="k \\* n"):
        COMPILED.float_planes(np.zeros(2, dtype="<i8"), 3, 0)
    with pytest.raises(ValueError, match="k \\* n"):
        COMPILED.float_planes(b"", 0, 2**62)  # no rows, but levels of 2^67 bytes


@pytest.mark.parametrize("path", ["compiled", "python"])
def test_float_deltas_take_only_64_bit_words(path):
    values = np.array([[1.5, 2.5, 3.25, 4.0, 5.0, 6.5]])
    if path == "python":
        with pytest.raises(TypeError, match="64-bit words"):
            python_path(columns.float_deltas, values)
        assert python_path(columns.float_deltas, values.view("<u8")) == python_path(columns.float_deltas, values.view("<i8"))
        return
    for wrong in (values, values.astype(np.int32)):
        with pytest.raises(TypeError, match="64-bit words"):
            columns.float_deltas(wrong)
    assert columns.float_deltas(values.view("<u8")) == columns.float_deltas(values.view("<i8"))
