"""Times as users type them, to integer nanoseconds since the Unix epoch."""

from __future__ import annotations

import datetime as dt
import re

from .errors import InvalidInputError

# A leading "-": before 1970. Stored stamps may be negative (a simulation's clock, a bag's
# header stamps from a zeroed clock), so a range must be able to name them.
_NS = re.compile(r"(-?\d+)ns")
_BARE = re.compile(r"-?\d+")
# A bare integer is read by its magnitude: below this it is seconds (1e11 s is the year
# 5138), from it on nanoseconds (1e11 ns is 100 s after 1970). `date +%s` and a simulation's
# 928 are seconds; a bag's 1432235695834049087 is nanoseconds.
BARE_SECONDS_BELOW = 10**11
TIME_RULE = ("TIME: ISO-8601 (2015-05-21T19:14:55.83Z, UTC without a zone), seconds (1432235695.83 "
             "or 12s), nanoseconds (1432235695834049087ns), or a bare integer: seconds below 1e11, "
             "else nanoseconds; a leading - is before 1970")
_SECONDS = re.compile(r"-?(\d+\.\d*|\.\d+|\d+(?:\.\d*)?s)")
# ISO-8601 with up to nanosecond fractions (datetime itself stops at microseconds).
_ISO = re.compile(
    r"(\d{4}-\d\d-\d\d(?:[T ]\d\d:\d\d(?::\d\d)?)?)(?:\.(\d{1,9}))?(Z|[+-]\d\d:?\d\d)?"
)


def parse_time(text: str) -> int:
    """Nanoseconds for "1432235695834049087ns", "1432235695.834" or "12s" (seconds),
    ISO-8601 "2015-05-21T19:14:55.834049087Z" (no zone means UTC), or a bare integer read
    by magnitude (seconds below BARE_SECONDS_BELOW, else nanoseconds)."""
    s = text.strip()
    if m := _NS.fullmatch(s):
        return int(m.group(1))
    if _BARE.fullmatch(s):
        n = int(s)
        return n * 1_000_000_000 if abs(n) < BARE_SECONDS_BELOW else n
    if _SECONDS.fullmatch(s):
        from decimal import Decimal, InvalidOperation  # here: most times are integers

        try:
            return int(Decimal(s.removesuffix("s")) * 1_000_000_000)
        except InvalidOperation:
            pass
    if m := _ISO.fullmatch(s):
        base, frac, zone = m.groups()
        try:
            when = dt.datetime.fromisoformat(base + (zone or ""))
        except ValueError as err:
            raise InvalidInputError(f"Time {text!r} is not a valid ISO-8601 date: {err}.") from None
        if when.tzinfo is None:
            when = when.replace(tzinfo=dt.timezone.utc)
        whole = when - dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc)
        seconds = whole.days * 86_400 + whole.seconds
        return seconds * 1_000_000_000 + int((frac or "").ljust(9, "0"))
    raise InvalidInputError(
        f"Time {text!r} is not understood; give nanoseconds (1432235695834049087ns), seconds "
        "(1432235695.83 or 12s) or ISO-8601 (2015-05-21T19:14:55.83Z)."
    )


_DURATION = re.compile(r"(\d+(?:\.\d*)?|\.\d+)\s*(ns|us|ms|s|min|h|d|w)?")
_UNIT_NS = {"ns": 1, "us": 1_000, "ms": 1_000_000, "s": 1_000_000_000, None: 1_000_000_000,
            "min": 60_000_000_000, "h": 3_600_000_000_000,
            "d": 86_400_000_000_000, "w": 604_800_000_000_000}  # fmt: skip


def parse_duration(text: str) -> int:
    """Nanoseconds for a duration such as "90s", "15min", "12h", "30d", "2w" (no unit:
    seconds)."""
    m = _DURATION.fullmatch(text.strip())
    if m is None:
        raise InvalidInputError(
            f"Duration {text!r} is not understood; give a number with a unit: ns, us, ms, s, "
            "min, h, d or w (e.g. 30d)."
        )
    from decimal import Decimal

    return int(Decimal(m.group(1)) * _UNIT_NS[m.group(2)])
