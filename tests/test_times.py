"""parse_time: nanoseconds, seconds and ISO-8601 all name the same instant."""

from __future__ import annotations

import pytest

from cclogfs.errors import InvalidInputError
from cclogfs.times import parse_duration, parse_time

T = 1432235695834049087


@pytest.mark.parametrize(
    "text, ns",
    [
        ("1432235695834049087", T),
        ("1432235695834049087ns", T),
        ("1432235695.834049087", T),
        ("1432235695.834049087s", T),
        ("2015-05-21T19:14:55.834049087Z", T),
        ("2015-05-21T21:14:55.834049087+02:00", T),
        ("2015-05-21 19:14:55.834049087", T),  # no zone: UTC
        ("2015-05-21T19:14:55.834Z", 1432235695834000000),
        ("2015-05-21", 1432166400000000000),
        ("12s", 12_000_000_000),
        ("0.5", 500_000_000),
        (" 928.8 ", 928_800_000_000),
        ("0", 0),
        ("1432235700", 1432235700_000_000_000),  # `date +%s`: seconds by magnitude
        ("928", 928_000_000_000),
        ("99999999999", 99999999999_000_000_000),
        ("100000000000", 100_000_000_000),  # from 1e11 on: nanoseconds
        # Before 1970, as stored stamps can be: "-5" was refused although `cat` showed such stamps.
        ("-5", -5_000_000_000),
        ("-5ns", -5),
        ("-0.5", -500_000_000),
        ("-12s", -12_000_000_000),
        ("-100000000000", -100_000_000_000),
        ("1969-12-31T23:59:59Z", -1_000_000_000),
    ],
)
def test_forms(text, ns):
    assert parse_time(text) == ns


@pytest.mark.parametrize("text", ["", "abc", "--5", "- 5", "1e9", "12 s", "2015-13-01", "2015-05-21T25:00Z"])
def test_rejected_with_explanation(text):
    with pytest.raises(InvalidInputError, match=r"Time .* (not understood|not a valid ISO-8601)"):
        parse_time(text)


@pytest.mark.parametrize(
    "text, ns",
    [("90s", 90 * 10**9), ("90", 90 * 10**9), ("1.5h", 5400 * 10**9), ("15min", 900 * 10**9),
     ("30d", 30 * 86400 * 10**9), ("2w", 14 * 86400 * 10**9), ("250ms", 250 * 10**6), ("7ns", 7)],
)  # fmt: skip
def test_durations(text, ns):
    assert parse_duration(text) == ns


@pytest.mark.parametrize("text", ["", "abc", "-5s", "5m", "5 years", "1e3s"])
def test_bad_durations_are_refused(text):
    with pytest.raises(InvalidInputError, match=r"Duration .* not understood"):
        parse_duration(text)
