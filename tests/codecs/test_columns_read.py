"""The decoder's whole-column integer arithmetic (columns_read) against the one-value
formulas it replaces: zigzag decoding of every word at once, and the wrap of float bits."""

from __future__ import annotations

import struct

from hypothesis import example, given
from hypothesis import strategies as st

from cclogfs.codecs.columns_read import _doubles, undo_zigzag_delta, unzigzag

U64 = st.integers(min_value=0, max_value=2**64 - 1)
EDGES = [0, 1, 2, 3, 2**63 - 1, 2**63, 2**63 + 1, 2**64 - 2, 2**64 - 1]


def one_at_a_time(v: int) -> int:
    """Zigzag decoding of one u64 as the format defines it, wrapped to i64."""
    d = (v >> 1) ^ -(v & 1)
    return ((d + 2**63) % 2**64) - 2**63


@given(st.lists(U64, max_size=300))
@example(EDGES)
@example([2**64 - 1] * 200)
def test_unzigzag_equals_the_formula_word_by_word(words):
    buf = struct.pack(f"<{len(words)}Q", *words)
    assert list(unzigzag(buf, len(words))) == [one_at_a_time(v) for v in words]


@given(st.lists(U64, min_size=1, max_size=50), st.integers(min_value=1, max_value=3))
def test_undo_zigzag_delta_wraps_sums_to_i64(words, order):
    d = [one_at_a_time(v) for v in words]
    for _ in range(order):
        d = [sum(d[: i + 1]) for i in range(len(d))]
    assert undo_zigzag_delta(words, order) == [((v + 2**63) % 2**64) - 2**63 for v in d]


@given(st.lists(st.integers(min_value=-(2**70), max_value=2**70), max_size=50))
@example([-(2**63), 2**63 - 1, 2**64 - 1, -1, 2**64, -(2**64)])
def test_doubles_take_the_bits_modulo_2_64(values):
    expect = [struct.unpack("<d", struct.pack("<Q", v % 2**64))[0] for v in values]
    got = _doubles(values)
    assert [struct.pack("<d", x) for x in got] == [struct.pack("<d", x) for x in expect]  # NaNs: bits
