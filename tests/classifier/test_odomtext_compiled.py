"""The compiled odometry reader (cclogfs/classifier/_odomtext.c) gives exactly the Python
path's (stamp, row): the same stamp, the same 13 doubles bit for bit, or None where the
Python path answers instead (another layout, a damaged text)."""

from __future__ import annotations

import json
import math
import struct
from decimal import Decimal

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cclogfs.classifier import features
from cclogfs.classifier.features import _odom_row_python, odom_row

COMPILED = features._odom_fields_c
pytestmark = pytest.mark.skipif(COMPILED is None, reason="cclogfs.classifier._odomtext is not built")

XYZ = ("x", "y", "z")


def odometry(stamp, values, *, seq=None, ros1=False, frame="odom", child="base_link", cov=(0.1, 1e6)):
    """An Odometry dict in rosbridge layout (json.dumps gives the layout the reader knows)."""
    sec, nsec = ("secs", "nsecs") if ros1 else ("sec", "nanosec")
    header = ({} if seq is None else {"seq": seq}) | {"stamp": {sec: stamp[0], nsec: stamp[1]}, "frame_id": frame}
    v = list(values)
    return {"header": header, "child_frame_id": child,
            "pose": {"pose": {"position": dict(zip(XYZ, v[0:3])), "orientation": dict(zip((*XYZ, "w"), v[3:7]))},
                     "covariance": list(cov)},
            "twist": {"twist": {"linear": dict(zip(XYZ, v[7:10])), "angular": dict(zip(XYZ, v[10:13]))},
                      "covariance": list(cov)}}  # fmt: skip


def with_numbers(numbers):
    """An Odometry text whose 13 values are these number tokens, as written."""
    return json.dumps(odometry((1, 2), [0.0] * 13, cov=())).replace("0.0", "%s") % tuple(numbers)


def bits(row):
    return [struct.pack("<d", v) for v in row]


def check_same(text):
    """The compiled answer, None or the Python path's exact (stamp, row)."""
    got = COMPILED(text)
    if got is None:
        return None
    want = _odom_row_python(text)
    assert got[0] == want[0] and type(got[0]) is int
    assert type(got[1]) is tuple and bits(got[1]) == bits(want[1]), text
    return got


# Numbers as robots write them: reprs of doubles of every magnitude (17 significant
# digits take float()'s slow path), and decimal strings of any length and exponent.
doubles = st.floats(allow_nan=True, allow_infinity=True) | st.floats(-1e3, 1e3)
decimals = st.builds(
    lambda sign, whole, frac, exp: f"{sign}{whole}.{frac}{exp}",
    st.sampled_from(["", "-"]), st.integers(0, 10**25), st.text("0123456789", min_size=1, max_size=25),
    st.sampled_from(["", "e5", "E-30", "e+2", "e-7", "e400", "e-400"]),
)  # fmt: skip
INSERTS = st.sampled_from(["", '"', "\\", "\\\\", "\n", "x", "-", " ", ",", "]", "}", "0", ".", "e", "1e5", "\xe9", "\u20ac"])


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(doubles, min_size=13, max_size=13), st.tuples(st.integers(0, 2**40), st.integers(0, 2**70)),
       st.none() | st.integers(0, 2**33), st.booleans(), st.text(max_size=5),
       st.lists(st.tuples(st.integers(0, 2000), st.integers(0, 3), INSERTS), max_size=4))  # fmt: skip
def test_the_same_rows_as_the_python_path(values, stamp, seq, ros1, frame, edits):
    text = json.dumps(odometry(stamp, values, seq=seq, ros1=ros1, frame=frame), ensure_ascii=False)
    got = check_same(text)
    fits = stamp[0] * 10**9 + stamp[1] < 2**63 and stamp[1] < 10**18
    if fits and all(ord(ch) < 256 for ch in text):  # what it must read itself
        assert got is not None
    for at, cut, insert in edits:  # damaged: None, or the same as the Python path
        at %= len(text) + 1
        check_same(text[:at] + insert + text[at + cut :])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(decimals, min_size=13, max_size=13))
def test_decimal_strings_convert_as_float_does(numbers):
    assert check_same(with_numbers(numbers)) is not None


def test_decimals_near_halfway_take_the_slow_path_correctly():
    """Decimals of up to 19 digits close to halfway between two doubles: the quick
    conversion cannot tell which way some round, so these test its fallback (two come
    from nav2_turtlebot.mcap's /odom; without the fallback both convert wrongly)."""
    numbers = ["-0.4167651345468599", "0.4998647928169693"]
    for x in (0.1, 1.0 / 3, 2.5e-4, 76.09624449125757, 123456.789, 0.008660916543229803, 0.9999100978456541):
        mid = (Decimal(x) + Decimal(math.nextafter(x, math.inf))) / 2
        numbers += [format(mid, f".{digits}f" if mid > 1 else f".{digits}g") for digits in (17, 18, 19)]
    numbers += [n[1:] if n.startswith("-") else "-" + n for n in numbers]
    for at in range(0, len(numbers), 13):
        part = (numbers[at:] + numbers)[:13]
        got = check_same(with_numbers(part))
        assert got is not None and bits(got[1]) == bits(map(float, part))


def test_layouts_it_leaves_to_python():
    msg = odometry((5, 6), [0.5] * 13)
    for text in (json.dumps(msg, indent=1), json.dumps(msg) + " ", json.dumps(msg | {"extra": 1}),
                 json.dumps(odometry((5, 6), [0.5] * 13, frame="\u20ac"), ensure_ascii=False)):  # fmt: skip
        assert COMPILED(text) is None
        assert odom_row(text)[0] == 5 * 10**9 + 6  # the Python path reads them
    assert COMPILED(json.dumps(msg)[:-1]) is None
    assert COMPILED(b"{}") is None and COMPILED(json.dumps(odometry((2**40, 0), [0.5] * 13))) is None


def test_real_odometry(shared_data):
    from bench._util import topic_messages

    texts = [t for _, t in topic_messages(shared_data("nav2_turtlebot.mcap"), "/odom")]
    assert len(texts) > 1000
    assert all(check_same(t) is not None for t in texts)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.lists(doubles, min_size=13, max_size=13) | st.sampled_from(["{}", "x", "\u20ac"]), max_size=8))
def test_a_list_at_once_flags_what_the_features_cannot_use(items):
    """`odom_rows_flagged`: each text's `odom_fields`, and the positions of every row that
    is None or holds a NaN or infinite value (pipeline.KeepUnscored looks only at those)."""
    texts = [item if isinstance(item, str) else json.dumps(odometry((3, 4), item)) for item in items]
    rows, flagged = features.odom_rows_flagged(texts)
    assert [r is None for r in rows] == [COMPILED(t) is None for t in texts]
    assert all(r is None or bits(r[1]) == bits(COMPILED(t)[1]) for r, t in zip(rows, texts))
    assert flagged == [i for i, r in enumerate(rows) if r is None or not all(map(math.isfinite, r[1]))]
