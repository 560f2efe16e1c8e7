"""Times as users type them, to integer nanoseconds since the Unix epoch."""

from __future__ import annotations

import datetime as dt
import re
from decimal import Decimal, InvalidOperation

from .errors import InvalidInputError

_NS = re.compile(r"(\d+)(?:ns)?")
_SECONDS = re.compile(r"(\d+\.\d*|\.\d+|\d+(?:\.\d*)?s)")
# ISO-8601 with up to nanosecond fractions (datetime itself stops at microseconds).
_ISO = re.compile(
    r"(\d{4}-\d\d-\d\d(?:[T ]\d\d:\d\d(?::\d\d)?)?)(?:\.(\d{1,9}))?(Z|[+-]\d\d:?\d\d)?"
)


def parse_time(text: str) -> int:
    """Nanoseconds for "1432235695834049087" (ns), "1432235695.834" or "12s" (seconds),
    or ISO-8601 "2015-05-21T19:14:55.834049087Z" (no zone means UTC)."""
    s = text.strip()
    if m := _NS.fullmatch(s):
        return int(m.group(1))
    if _SECONDS.fullmatch(s):
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
        f"Time {text!r} is not understood; give nanoseconds (1432235695834049087), seconds "
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
    return int(Decimal(m.group(1)) * _UNIT_NS[m.group(2)])
