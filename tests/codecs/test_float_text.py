"""The columnar codec's float texts: the orjson fast path gives exactly what json.dumps writes.

Bytes on disk rest on this: a float column is kept only when its rendering gives every
token back, and decoding renders the same way. The reference is the path the codec took
before orjson (repr, with json's NaN and Infinity).
"""

from __future__ import annotations

import json
import math

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from cclogfs.codecs.columns import _as_floats, _render_floats, _render_joined, classify
from cclogfs.codecs.columnar_format import ColumnKind


def reference_texts(values: list[float]) -> list[str]:
    """Each float as json.dumps writes it: repr, or NaN / Infinity / -Infinity."""
    return [json.dumps(v) for v in values]


def reference_as_floats(tokens: tuple[str, ...]) -> bool:
    """Whether the old check accepted the tokens as a FLOAT column."""
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        return False
    return reference_texts(values) == list(tokens)


# Where orjson and repr part ways: exponent forms (below 1e-4 and from 1e16 up) and the
# decade below 1e-4, which orjson writes in full ("0.00001") and repr as "1e-05".
_EDGES = [0.0, -0.0, 1e-4, 1e-5, 1e-6, 9.999999999999999e-05, 1e16, 9999999999999998.0, 1e15, 5e-324,
          2.2250738585072014e-308, 1.7976931348623157e308, 0.1, 1.0, -1e-4, 123456789012345.6,
          math.nan, math.inf, -math.inf]  # fmt: skip
_EDGES += [float(np.nextafter(v, d)) for v in (1e-4, 1e-5, 1e16) for d in (0.0, math.inf)]

floats = st.one_of(st.floats(), st.sampled_from(_EDGES), st.floats(min_value=-1e-3, max_value=1e-3))


@given(st.lists(floats, max_size=50))
@settings(max_examples=2000, deadline=None)
@example(_EDGES)
def test_render_is_json_dumps(values):
    assert _render_floats(np.array(values, dtype=np.float64)) == reference_texts(values)


def _spellings(v: float) -> list[str]:
    """The reference text of v and spellings that denote the same value but are not it."""
    ref = json.dumps(v)
    out = [ref, f"{v:.17g}", f"{v:e}", ref.replace("e-0", "e-").replace("e+", "e"), ref.upper()]
    if math.isfinite(v) and v != 0:
        out.append(format(v, "f"))  # 1e-05 as 0.000010, 1e16 as 10000000000000000.000000
        out.append(np.format_float_positional(v))  # 1e-05 as 0.00001: orjson's text
    return out


@given(st.lists(floats, min_size=1, max_size=40), st.data())
@settings(max_examples=1000, deadline=None)
def test_float_check_is_the_reference_check(values, data):
    tokens = tuple(data.draw(st.sampled_from(_spellings(v))) for v in values)
    accepted = _as_floats(tokens) is not None
    assert accepted == reference_as_floats(tokens), tokens


@given(st.lists(st.sampled_from(_EDGES[:12]), min_size=20, max_size=40))
@settings(max_examples=300, deadline=None)
def test_long_columns_take_the_same_path(values):
    """From 16 tokens simdjson parses them; the outcome is still the reference's."""
    tokens = tuple(json.dumps(v) for v in values)
    kind, _ = classify(tokens)
    assert kind in (ColumnKind.FLOAT, ColumnKind.CONST, ColumnKind.DECIMAL, ColumnKind.INT)
    for broken in (tokens[:-1] + (np.format_float_positional(values[-1]),),):
        assert (_as_floats(broken) is not None) == reference_as_floats(broken)



@given(st.lists(floats, min_size=1, max_size=50))
@settings(max_examples=1000, deadline=None)
@example(_EDGES)
@example([1e-5, 10.00001, 0.0, 1e-300, math.nan])
# around the bound below which the encoder respells orjson's items (columns._RESPELL_BELOW)
@example([math.nextafter(1e-4, 0), 1e-4, math.nextafter(1e-4, 1), -9.9999e-5, 1.0001e-4,
          math.nextafter(1.0001e-4, 0), -0.0, 5e-324, 1e16, math.nextafter(1e16, 0), -math.inf])
def test_the_encoder_s_joined_rendering_is_json_dumps(values):
    assert _render_joined(np.array(values, dtype=np.float64)) == ",".join(reference_texts(values))
