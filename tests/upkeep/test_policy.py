"""Aging policies: rounding stays within each field's bound and touches nothing else."""

from __future__ import annotations

import json
import math
import re
from decimal import ROUND_HALF_EVEN, Decimal, localcontext
from fnmatch import fnmatchcase

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.upkeep.policy import Grid, Policy, Rule, grid_step, parse_rule
from cclogfs.errors import InvalidInputError

TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|-?[0-9][-+.eE0-9]*')
KEYS = st.sampled_from(["x", "y", "pose", "twist", "covariance", "a.b", "sec", "n"])
FLOATS = st.floats(allow_nan=False, allow_infinity=False, width=64) | st.floats(-1e3, 1e3)
SCALARS = FLOATS | st.integers(-(2**63), 2**63) | st.text(max_size=5) | st.booleans() | st.none()
DOCS = st.recursive(
    SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(KEYS, inner, max_size=4),
    max_leaves=20,
)
RULES = st.lists(
    st.builds(
        Rule,
        st.sampled_from(["**", "x", "*.x", "pose.**", "**.covariance", "twist.*", "a.b"]),
        st.sampled_from([0.0, 1e-9, 1e-4, 1e-3, 0.05, 0.3, 7.0]),
    ),
    min_size=1,
    max_size=4,
)


def blank_numbers(text: str) -> str:
    return TOKEN.sub(lambda m: m.group() if m.group()[0] == '"' else "#", text)


def leaves(value, path=()):
    """(path, value) of every scalar, with array levels adding no part (the module's rule)."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from leaves(v, path + (k,))
    elif isinstance(value, list):
        for v in value:
            yield from leaves(v, path)
    else:
        yield path, value


def expected_bound(rules, path) -> float:
    """The bound of the last rule that matches, by a table walk apart from the module's."""
    bound = 0.0
    for rule in rules:
        pat = rule.pattern.split(".")
        # ok[i][j]: the first i pattern parts match the first j path parts
        ok = [[False] * (len(path) + 1) for _ in range(len(pat) + 1)]
        ok[0][0] = True
        for i, part in enumerate(pat, 1):
            for j in range(len(path) + 1):
                if part == "**":
                    ok[i][j] = ok[i - 1][j] or (j > 0 and ok[i][j - 1])
                else:
                    ok[i][j] = j > 0 and ok[i - 1][j - 1] and fnmatchcase(path[j - 1], part)
        if ok[-1][-1]:
            bound = rule.bound
    return bound


@settings(max_examples=300, deadline=None)
@given(DOCS, RULES, st.sampled_from([None, 0, 2]))
def test_rounding_stays_within_bounds_and_keeps_everything_else(doc, rules, indent):
    text = json.dumps(doc, indent=indent)
    policy = Policy(rules)
    aged = policy.round_text(text)
    back = json.loads(aged)
    before, after = list(leaves(doc)), list(leaves(back))
    assert [p for p, _ in before] == [p for p, _ in after]
    for (path, old), (_, new) in zip(before, after):
        assert type(old) is type(new), (path, old, new)
        if isinstance(old, float):
            bound = expected_bound(rules, path)
            assert policy.bound_for(path) == bound
            step = grid_step(bound)
            if step is None or not abs(old) < 1e15:
                assert new == old
            else:
                assert abs(new - old) <= bound, (path, old, new, bound)
        else:
            assert new == old
    # Rounding to the same grid again changes nothing.
    assert policy.round_text(aged) == aged
    # Every byte outside number tokens is untouched (whitespace, keys, strings).
    assert blank_numbers(aged) == blank_numbers(text)


def test_only_number_tokens_change():
    text = '{"frame_id": "odom 1.23456", "x":  1.23456,\n "n": 7, "z": -0.0001, "e": 1E-05}'
    aged = Policy([parse_rule("1e-3")]).round_text(text)
    assert aged == '{"frame_id": "odom 1.23456", "x":  1.234,\n "n": 7, "z": 0.000, "e": 0.000}'


def test_last_matching_rule_wins_and_zero_keeps_exact():
    policy = Policy([parse_rule("1e-3"), parse_rule("header.**=0"), parse_rule("pose.covariance=0.05")])
    text = '{"header": {"t": 1.23456}, "pose": {"covariance": [0.1234, 2.96], "x": 1.23456}}'
    assert policy.round_text(text) == '{"header": {"t": 1.23456}, "pose": {"covariance": [0.1, 3.0], "x": 1.234}}'


def test_grid_steps_follow_the_1_2_5_series():
    assert [str(grid_step(b)) for b in (1e-3, 5e-4, 0.01, 0.3, 1.0, 7.3e-5)] == [
        "0.002", "0.001", "0.02", "0.5", "2", "0.0001",
    ]  # fmt: skip
    assert grid_step(0.0) is None and grid_step(1e-20) is None


@settings(max_examples=300, deadline=None)
@given(st.integers(-(10**14), 10**14), st.sampled_from([1e-3, 0.05, 0.3, 7.0, 1e-9]), st.integers(-3, 3))
def test_ties_and_near_ties_round_half_even_exactly(k, bound, nudge):
    """Tokens on and next to a midpoint between grid points agree with exact decimals."""
    step = grid_step(bound)
    tie = (Decimal(k) + Decimal("0.5")) * step + Decimal(nudge).scaleb(-20)
    token = format(tie, "f")
    if not abs(float(token)) < 1e15:
        return
    with localcontext() as ctx:
        ctx.prec = 60  # the default 28 digits would round the quotient itself
        exact = (Decimal(token) / step).to_integral_value(rounding=ROUND_HALF_EVEN) * step
    aged = Grid(step, bound).round(token)
    if abs(float(exact) - float(token)) <= bound:
        assert Decimal(aged) == exact
    else:  # exact half-even lands one float rounding over the bound: the other side, or kept
        assert aged == token or abs(Decimal(aged) - exact) == step
        assert abs(float(aged) - float(token)) <= bound


TIE_BOUNDS = st.sampled_from([1e-3, 5e-4, 0.01, 0.05, 0.3, 1.0, 7.0, 1e-6, 1e-9, 2.5e-3])


@settings(max_examples=1000, deadline=None)
@given(
    TIE_BOUNDS,
    st.integers(-(10**12), 10**12) | st.integers(-2000, 2000),
    st.sampled_from([Decimal("0.5"), Decimal("0.4999"), Decimal("0.5001"), Decimal(0)]),
    st.integers(0, 3),
)
def test_aged_ties_never_exceed_the_bound_in_float64(bound, k, frac, extra_places):
    """Ties (-24.375 at bound 1e-3 became -24.376: 0.0010000000000012 away) and values
    next to them, written with a few more decimals or none: every aged value is within the
    bound exactly as a reader checks it, with float64 subtraction and no slack."""
    step = grid_step(bound)
    value = (Decimal(k) + frac) * step
    token = format(value.quantize(Decimal(1).scaleb(value.as_tuple().exponent - extra_places)), "f")
    if "." not in token:
        token += ".0"
    aged = Policy([Rule("x", bound)]).round_text('{"x": %s}' % token)
    old, new = float(token), json.loads(aged)["x"]
    assert abs(old - new) <= bound, (token, aged, abs(old - new), bound)


@settings(max_examples=1000, deadline=None)
@given(TIE_BOUNDS, st.floats(-1e6, 1e6, allow_nan=False) | st.floats(allow_nan=False, allow_infinity=False))
def test_aged_values_never_exceed_the_bound_in_float64(bound, value):
    token = repr(value) if ("." in repr(value) or "e" in repr(value)) else repr(value) + ".0"
    aged = Policy([Rule("**", bound)]).round_text(f'[{token}]')
    assert abs(value - json.loads(aged)[0]) <= bound, (token, aged, bound)


def test_the_reported_tie_stays_within_its_bound():
    aged = Policy([parse_rule("1e-3")]).round_text('{"x": -24.375, "y": 1.003, "z": -0.003}')
    back = json.loads(aged)
    assert abs(back["x"] - -24.375) <= 1e-3 and abs(back["y"] - 1.003) <= 1e-3 and abs(back["z"] - -0.003) <= 1e-3
    # Both grid neighbours of -24.375 are 0.0010000000000012 away in float64: it stays.
    assert aged == '{"x": -24.375, "y": 1.002, "z": -0.004}'


def test_thinning_keeps_first_and_last_and_the_rate():
    msgs = [(i * 10_000_000, "{}") for i in range(101)]  # 100 Hz for 1 s
    kept = Policy(max_rate_hz=10).thin(msgs)
    assert kept[0] == msgs[0] and kept[-1] == msgs[-1]
    assert len(kept) == 11
    gaps = [b[0] - a[0] for a, b in zip(kept, kept[1:])]
    assert min(gaps) >= 100_000_000


@pytest.mark.parametrize("n", [2, 3, 4, 105, 106, 109, 110])
def test_thinning_holds_the_rate_at_the_end_of_a_window_too(n):
    """The last message was kept however close it came after the one kept before it: twice
    the rate at each window's end (found by attack: compact --max-rate 2, tuc_corridor)."""
    msgs = [(i * 10_000_000, "{}") for i in range(n)]  # 100 Hz
    policy = Policy(max_rate_hz=10)
    kept = policy.thin(msgs)
    assert kept[0] == msgs[0] and kept[-1] == msgs[-1]
    if len(kept) > 2:
        assert min(b[0] - a[0] for a, b in zip(kept, kept[1:])) >= 100_000_000
    assert len(kept) == max(2, 1 + (n - 1) // 10) if n > 1 else 1
    assert policy.thin(kept) == kept  # aging again changes nothing


@pytest.mark.parametrize(
    "text, match",
    [("abc", "BOUND or PATTERN=BOUND"), ("x=-1", ">= 0"), ("x=nan", ">= 0"), ("a..b=1", "empty part")],
)
def test_bad_rules_are_refused(text, match):
    with pytest.raises(InvalidInputError, match=match):
        parse_rule(text)


def test_a_policy_needs_something_to_do():
    with pytest.raises(InvalidInputError, match="error bound or a max rate"):
        Policy()
    with pytest.raises(InvalidInputError, match="max rate"):
        Policy(max_rate_hz=0)


def test_non_json_is_refused():
    with pytest.raises(InvalidInputError, match="not JSON"):
        Policy([parse_rule("1e-3")]).round_text('{"x": 1.5, oops}')
