"""Lower fidelity for old data: float values rounded within stated error bounds.

A `Policy` says, per field, how far a value may move (an absolute bound), and optionally
how many messages per second of each window to keep. `Policy.age(messages)` gives the new
texts. Only number tokens with a fraction or exponent change, and only inside the JSON
text: keys, strings, integers (stamps, counters), whitespace and every other byte stay as
they were, so a message still parses to the same structure with the same types.

A value is rounded to a grid step q from the 1-2-5 series with q <= 2 * bound, and written
as a fixed-point decimal (`0.125`, `-3.500`, zero always as `0.000`). Exact decimal
arithmetic keeps |new - old| <= q / 2 <= bound for the decimal values, but with q = 2 *
bound a tie (-24.375 at bound 0.001) sits exactly on the bound, and read back as float64
the difference can come out one rounding above it (0.0010000000000012). So every rounded
value is checked as a reader would check it, `abs(float(old) - float(new)) <= bound`;
one that fails takes the grid point on the other side of the value, and if that fails
too the token stays as it was. Fixed-point tokens are what the columnar codec stores as
integers, which is where the space goes.

Field paths are the object keys from the message root joined by dots; array levels do not
add a part (every element of `pose.covariance` has the path `pose.covariance`). In a
pattern `*` matches one part and `**` any number of parts (also none). When several rules
match, the last one wins, so a general bound comes first and exceptions after it; a bound
of 0 keeps the field exact.

This module knows nothing of storage or of the classifier: `upkeep.job` wires it to the
store.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from decimal import ROUND_HALF_EVEN, Decimal, localcontext
from fnmatch import fnmatchcase
from typing import Any, Iterable, Sequence

from ..errors import InvalidInputError

__all__ = ["Policy", "Rule", "grid_step", "parse_rule"]

NS = 1_000_000_000
# Values this large are left alone: their fixed-point form would not fit the columnar
# codec's 64-bit integers, and no robot field needs them rounded.
MAX_ROUNDED = 1e15
# Tokens: a JSON string (kept as is: it may hold digits) or a JSON number.
_TOKEN = re.compile(r'("(?:[^"\\]|\\.)*"|-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?)')
# Whole structure: strings, numbers, punctuation, literals, with whitespace between.
_LEX = re.compile(
    r'\s*(?:("(?:[^"\\]|\\.)*")|(-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?)'
    r"|([{}\[\]:,])|(true|false|null|NaN|-?Infinity))"
)
_SHAPE_CACHE_MAX = 256
# The finest grid: 18 decimals, the most a 64-bit fixed-point integer can carry.
MIN_STEP = Decimal("1e-18")


@dataclass(frozen=True)
class Rule:
    """Values whose path matches `pattern` may move by at most `bound` (0 keeps them)."""

    pattern: str
    bound: float

    def __post_init__(self) -> None:
        if not (isinstance(self.bound, (int, float)) and math.isfinite(self.bound) and self.bound >= 0):
            raise InvalidInputError(f"Error bound for {self.pattern!r} must be a finite number >= 0, got {self.bound!r}.")
        if not self.pattern or any(not p for p in self.pattern.split(".")):
            raise InvalidInputError(f"Field pattern {self.pattern!r} has an empty part.")

    def matches(self, path: tuple[str, ...]) -> bool:
        return _match(tuple(self.pattern.split(".")), path)


def _match(pattern: tuple[str, ...], path: tuple[str, ...]) -> bool:
    if not pattern:
        return not path
    head, rest = pattern[0], pattern[1:]
    if head == "**":
        return any(_match(rest, path[i:]) for i in range(len(path) + 1))
    return bool(path) and fnmatchcase(path[0], head) and _match(rest, path[1:])


def _number_paths(value: Any, path: tuple[str, ...], out: set[tuple[str, ...]]) -> None:
    """Add the path of every number in a JSON value to `out` (array levels add no part)."""
    if isinstance(value, dict):
        for key, item in value.items():
            _number_paths(item, (*path, key), out)
    elif isinstance(value, list):
        for item in value:
            _number_paths(item, path, out)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        out.add(path)


def parse_rule(text: str) -> Rule:
    """`BOUND` (every field) or `PATTERN=BOUND`, e.g. `1e-3` or `pose.covariance=0.01`."""
    pattern, sep, bound = text.rpartition("=")
    if not sep:
        pattern = "**"
    try:
        value = float(bound)
    except ValueError:
        raise InvalidInputError(
            f"Error rule {text!r}: expected BOUND or PATTERN=BOUND with a number, e.g. "
            "'1e-3' or 'pose.covariance=0.01'."
        ) from None
    return Rule(pattern.strip(), value)


def grid_step(bound: float) -> Decimal | None:
    """The largest step of the 1-2-5 series (1, 2, 5 x 10^k) not above 2 * bound; None
    (keep the value exact) for 0 and for bounds finer than 1e-18 allows."""
    if bound <= 0:
        return None
    target = Decimal(repr(2 * bound))
    exp = target.adjusted()
    step = next(Decimal(m).scaleb(exp) for m in (5, 2, 1) if Decimal(m).scaleb(exp) <= target)
    return step if step >= MIN_STEP else None


class Grid:
    """Rounding to multiples of one step, written with a fixed number of decimals."""

    def __init__(self, step: Decimal, bound: float):
        self.step = step
        self.bound = bound
        exp = step.as_tuple().exponent
        mantissa = int(step.scaleb(-exp))  # 1, 2 or 5
        self.places = max(1, -exp)
        # value = m * step = (m * unit) / 10^places, with unit an integer
        self.unit = mantissa * 10 ** (exp + self.places)
        self.step_f = float(step)
        self._cache: dict[str, str] = {}

    def round(self, token: str) -> str:
        """The fixed-point token nearest to `token` on this grid (`token` if too large)."""
        out = self._cache.get(token)
        if out is None:
            out = self._round(token)
            if len(self._cache) >= 4096:
                self._cache.clear()
            self._cache[token] = out
        return out

    def _round(self, token: str) -> str:
        value = float(token)
        if not abs(value) < MAX_ROUNDED:
            return token
        x = value / self.step_f
        # float arithmetic picks the nearest grid point unless x is within float error
        # (a few ulps of x, with a wide margin) of a tie; those, and values too large
        # for it, go through exact decimal arithmetic.
        if abs(x) < 2**52 and abs(x - math.floor(x) - 0.5) > 1e-9 + abs(x) * 1e-14:
            m = round(x)
        else:
            with localcontext() as ctx:
                ctx.prec = 60  # |value| < 1e15 over a step >= 1e-18 needs 33 digits
                m = int((Decimal(token) / self.step).to_integral_value(rounding=ROUND_HALF_EVEN))
        out = self._fixed(m)
        moved = float(out) - value
        if abs(moved) <= self.bound:
            return out
        # Over the bound in float64 (a tie or near-tie): the grid point on the value's other
        # side is as near in decimals and may pass; else the value stays exact.
        other = self._fixed(m - 1 if moved > 0 else m + 1)
        return other if abs(float(other) - value) <= self.bound else token

    def _fixed(self, m: int) -> str:
        """Grid point `m` (m * step) as a fixed-point token."""
        n = m * self.unit
        digits = str(abs(n)).rjust(self.places + 1, "0")
        sign = "-" if n < 0 else ""  # zero is never written "-0.000"
        return f"{sign}{digits[: -self.places]}.{digits[-self.places :]}"


@dataclass
class Policy:
    """How old windows lose fidelity: rounding rules, and at most `max_rate_hz` messages
    per second of each window (None keeps them all)."""

    rules: Sequence[Rule] = ()
    max_rate_hz: float | None = None
    _shapes: dict = field(default_factory=dict, repr=False, compare=False)
    _grids: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.rules = tuple(self.rules)
        if self.max_rate_hz is not None and not (math.isfinite(self.max_rate_hz) and self.max_rate_hz > 0):
            raise InvalidInputError(f"max rate must be a number > 0 (Hz), got {self.max_rate_hz!r}.")
        if not self.rules and self.max_rate_hz is None:
            raise InvalidInputError("An aging policy needs an error bound or a max rate.")

    def describe(self) -> dict[str, Any]:
        """The policy as JSON-able data, as stored in an aged window's metadata."""
        return {"rules": [[r.pattern, r.bound] for r in self.rules], "max_rate_hz": self.max_rate_hz}

    def _grid(self, bound: float) -> Grid | None:
        """One Grid per bound, so their token caches are shared across shapes."""
        if bound not in self._grids:
            step = grid_step(bound)
            self._grids[bound] = None if step is None else Grid(step, bound)
        return self._grids[bound]

    def unmatched(self, texts: Iterable[str]) -> list[Rule]:
        """The rules whose pattern matches no number field of any of `texts`: a misspelt
        field or a `msg.` prefix, which would leave that field to the other rules (rounded
        for good, where it was meant to stay exact) and say nothing."""
        paths: set[tuple[str, ...]] = set()
        for text in texts:
            _number_paths(json.loads(text), (), paths)
        return [rule for rule in self.rules if not any(rule.matches(path) for path in paths)]

    def bound_for(self, path: Sequence[str]) -> float:
        """The bound that applies to a field path (0 when no rule matches)."""
        bound = 0.0
        for rule in self.rules:
            if rule.matches(tuple(path)):
                bound = rule.bound
        return bound

    # -- texts ---------------------------------------------------------------------------

    def age(self, messages: Sequence[tuple[int, str]]) -> list[tuple[int, str]]:
        """The window's messages at this policy's fidelity: thinned to the max rate (the
        first and last message always stay, so the window keeps its time span), then
        rounded."""
        kept = self.thin(messages)
        if not self.rules:
            return list(kept)
        return [(stamp, self.round_text(text)) for stamp, text in kept]

    def thin(self, messages: Sequence[tuple[int, str]]) -> list[tuple[int, str]]:
        if self.max_rate_hz is None or len(messages) <= 2:
            return list(messages)
        gap = NS / self.max_rate_hz
        out = [messages[0]]
        for item in messages[1:-1]:
            if item[0] - out[-1][0] >= gap:
                out.append(item)
        # The last message keeps the window's extent; the one kept before it goes when
        # closer than the gap, else the window held up to twice the rate at its end (up to
        # 4 messages in one second at --max-rate 2 on tuc_corridor).
        if len(out) > 1 and messages[-1][0] - out[-1][0] < gap:
            out[-1] = messages[-1]
        else:
            out.append(messages[-1])
        return out

    def round_text(self, text: str) -> str:
        """`text` with every number token that a rule covers rounded to its grid."""
        parts = _TOKEN.split(text)  # odd items are tokens: strings and numbers
        numbers = [i for i in range(1, len(parts), 2) if parts[i][0] != '"']
        if not numbers:
            return text
        # Messages of one topic share their shape: the text with its numbers blanked out
        # is the key to the per-number decisions, so each shape is parsed only once.
        blank = parts.copy()
        for i in numbers:
            blank[i] = "#"
        shape = "".join(blank)
        slots = self._shapes.get(shape)
        if slots is None:
            try:
                slots = self._slots(text)
            except (IndexError, json.JSONDecodeError):  # the lexer follows JSON's nesting and strings
                raise InvalidInputError("Cannot age a message that is not JSON (its nesting is broken).") from None
            if len(self._shapes) >= _SHAPE_CACHE_MAX:
                self._shapes.clear()
            self._shapes[shape] = slots
        if len(slots) != len(numbers):  # pragma: no cover - both scans share one grammar
            raise InvalidInputError("Cannot age a message whose numbers do not match its shape.")
        changed = False
        for i, grid in zip(numbers, slots):
            token = parts[i]
            if grid is not None and ("." in token or "e" in token or "E" in token):
                parts[i] = grid.round(token)
                changed = True
        return "".join(parts) if changed else text

    def _slots(self, text: str) -> list[tuple[Decimal, Decimal] | None]:
        """Per number token in order: the Grid its rule gives, or None to keep it."""
        out: list[tuple[Decimal, Decimal] | None] = []
        # Stack of containers: for an object, the key being read; for an array, None.
        stack: list[list] = []
        path: list[str] = []
        pos, n = 0, len(text)
        expect_key = False
        while pos < n:
            m = _LEX.match(text, pos)
            if m is None:
                if text[pos:].strip() == "":
                    break
                raise InvalidInputError(f"Cannot age a message that is not JSON (character {pos}).")
            pos = m.end()
            string, number, punct, literal = m.groups()
            if punct == "{":
                stack.append(["obj", None])
                expect_key = True
            elif punct == "[":
                stack.append(["arr", None])
            elif punct in ("}", "]"):
                if not stack:  # a close with nothing open: not JSON (`]`, `{"a":1}}`)
                    raise InvalidInputError(f"Cannot age a message that is not JSON (character {pos - 1}).")
                kind, key = stack.pop()
                if stack and stack[-1][0] == "obj":
                    path.pop()
            elif punct == ":":
                expect_key = False
            elif punct == ",":
                expect_key = bool(stack) and stack[-1][0] == "obj"
            elif string is not None:
                if expect_key:
                    path.append(json.loads(string))
                    continue
                if stack and stack[-1][0] == "obj":
                    path.pop()
            else:
                if number is not None:
                    out.append(self._grid(self.bound_for(path)))
                if stack and stack[-1][0] == "obj":
                    path.pop()
        return out
