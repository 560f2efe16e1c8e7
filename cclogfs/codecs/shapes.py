"""Split JSON texts into a shape (the literal text between values) and value tokens.

A text is cut into `literals[0] value[0] literals[1] ... value[k-1] literals[k]`, where the
literals hold everything that is not a value: braces, brackets, commas, colons, whitespace
and object keys. Texts with the same literals share a shape. Because the pieces are cut
out of the text, joining them gives the text back byte for byte, whatever its spelling;
a text the tokenizer cannot cut completely (not JSON-like) has no shape.
"""

from __future__ import annotations

import re
from collections import OrderedDict
from collections.abc import Sequence
from itertools import chain, repeat
from operator import itemgetter

__all__ = ["ShapeMatcher", "column_tokens", "split_text"]

# The compiled row finder (cclogfs/codecs/_rows.c; setup.py builds it where a C compiler is):
# the same rows as `_rows_python`, or the same tokens by column (`_columns`), in half the
# time per window (bench/record_floor.py). Tests and benchmarks set both to None to take
# the re module's path.
try:
    from ._rows import match_columns as _match_columns_c, match_rows as _match_rows_c
except ImportError:
    _match_rows_c = _match_columns_c = None

_STRING = r'"[^"\\]*(?:\\.[^"\\]*)*"'
_NUMBER = r"[-+.0-9A-Za-z]++"  # numbers, true/false/null, NaN, Infinity
# The text between two values: punctuation, whitespace and keys.
_BETWEEN = r"(?:[\s{}\[\],:]++|" + _STRING + r"\s*+:)*+"
# Possessive quantifiers: a text that does not tokenize fails fast instead of backtracking.
_TOKEN = re.compile("(" + _BETWEEN + ")(" + _STRING + "|" + _NUMBER + ")", re.S)
_LITERAL = re.compile(_BETWEEN, re.S)
# Shapes with more value slots than this have no matcher (their texts are grouped by
# split_text alone).
_MAX_MATCHER_SLOTS = 4096
# Shapes whose literals hold more characters than this, or with more value slots, are not
# compiled into a regex: the re module spends ~1.3 us and ~130 bytes a literal character
# (a message with a 4 MiB string took 5.5 s and 541 MiB) and 60-90 us a value slot
# compiling one (20 messages of ~2,000 numbers, a new shape each as the array length
# varies, took 4-5 s). _LongShape finds the same values at linear cost without compiling.
_MAX_REGEX_LITERALS = 4096
_MAX_REGEX_SLOTS = 256
# Messages besides the first that decide which values of a shape are constant.
_PROBES = 4
# Rounds of specialized matching before the rest of a window is grouped text by text.
_MAX_ROUNDS = 8


def split_text(text: str) -> tuple[tuple[str, ...], list[str]] | None:
    """(literals, values) of a text, or None when the pieces would not rebuild it."""
    pairs = _TOKEN.findall(text)
    joined = "".join(chain.from_iterable(pairs))
    # findall silently skips characters no token matches; then the pieces fall short.
    if not text.startswith(joined):
        return _split_keyed_tail(text)
    # map/itemgetter, not generators: ~3x faster on a message of 80,000 values.
    literals = tuple(map(itemgetter(0), pairs)) + (text[len(joined) :],)
    return literals, list(map(itemgetter(1), pairs))


def _split_keyed_tail(text: str) -> tuple[tuple[str, ...], list[str]] | None:
    """split_text of a text whose last value is followed by a key, as in
    `{"ranges": [1.5], "intensities": []}`, or of a text with keys but no value at all.

    Such a tail is literal text, but no token ends it, so findall goes on searching inside
    it and cuts the key's letters as a number: the pieces skip the key's opening quote and
    fall short. Here tokens are taken only while each starts where the last ended, and
    the rest must be literal text alone (punctuation, whitespace, keys).
    """
    literals, values, at = [], [], 0
    for match in _TOKEN.finditer(text):
        if match.start() != at:
            break
        literals.append(match[1])
        values.append(match[2])
        at = match.end()
    if _LITERAL.fullmatch(text, at) is None:
        return None
    literals.append(text[at:])
    return tuple(literals), values


def _kinds(values: Sequence[str]) -> tuple[bool, ...]:
    """Whether each value is a string (else a number, true, false or null)."""
    return tuple(map(str.startswith, values, repeat('"')))


def _matcher(literals: tuple[str, ...], values: list[str]) -> re.Pattern[str] | _LongShape | None:
    """What matches exactly the texts of this shape, one group per value.

    Where the compiled row finder is built, a _LongShape for every shape: it reads the
    values without compiling anything, where a regex costs ~1.3 us a literal character to
    compile (smart logging stores a window of its own shape nearly every time: 458 regexes
    of ~0.55 ms for the 300k-line speed bench, 4.5 % of `record --model`; issue 14)."""
    if len(values) > _MAX_MATCHER_SLOTS:
        return None
    if _match_rows_c is not None or not _regex_is_cheap(literals, len(values)):
        return _LongShape(literals, _kinds(values))
    return _regex(literals, _kinds(values))


def _regex_is_cheap(literals: tuple[str, ...], slots: int) -> bool:
    return slots <= _MAX_REGEX_SLOTS and sum(map(len, literals)) <= _MAX_REGEX_LITERALS


def _regex(literals: tuple[str, ...], kinds: tuple[bool, ...]) -> re.Pattern[str]:
    """The regex of a shape (kinds: whether each value slot holds a string)."""
    parts = []
    for lit, is_string in zip(literals, kinds):
        parts.append(re.escape(lit))
        parts.append("(" + (_STRING if is_string else _NUMBER) + ")")
    parts.append(re.escape(literals[-1]))
    return re.compile("".join(parts), re.S)


def _skipper(literals: tuple[str, ...], kinds: tuple[bool, ...]) -> re.Pattern[str] | None:
    """A regex that skips each literal by its length and captures the values between.

    Cheaper than matching the literal characters (one step per literal, not per
    character); what it finds must be checked against the literals (see _rows).
    """
    if len(kinds) > _MAX_MATCHER_SLOTS:
        return None
    parts = []
    for lit, is_string in zip(literals, kinds):
        parts.append(".{%d}(%s)" % (len(lit), _STRING if is_string else _NUMBER))
    parts.append(".{%d}" % len(literals[-1]))
    return re.compile("".join(parts), re.S)


# One value token at a position, as the matcher regex's groups take them.
_STRING_AT = re.compile(_STRING, re.S)
_NUMBER_AT = re.compile(_NUMBER)


class _Found:
    """What `_LongShape.fullmatch` found: the values, as `re.Match.groups()` gives them."""

    __slots__ = ("_values",)

    def __init__(self, values: tuple[str, ...]):
        self._values = values

    def groups(self) -> tuple[str, ...]:
        return self._values


class _LongShape:
    """`_regex` of a shape without compiling it: the same matches, linear cost. For every
    shape where the compiled row finder is built; else for a shape with long literals or
    many value slots (named for those, the first use).

    A text is read literal by literal and value by value: literals fix where each value
    starts, and each value token can end in one place only (a string at its first
    unescaped quote, a number possessively), so these are the regex's values. The
    compiled row finder (`_rows.c`) reads the same way where it is built; else the re
    module reads one token at a time.
    """

    def __init__(self, literals: tuple[str, ...], kinds: tuple[bool, ...]):
        self._literals = literals
        self._kinds = kinds
        self._tokens = [_STRING_AT.match if is_string else _NUMBER_AT.match for is_string in kinds]
        # A short shape's regex, compiled the first time a text is one the compiled row
        # finder declines (a character beyond Latin-1): faster than a token at a time.
        self.short = _regex_is_cheap(literals, len(kinds))
        self._compiled: re.Pattern[str] | None = None

    def fullmatch(self, text: str) -> _Found | re.Match[str] | None:
        if _match_rows_c is not None:
            rows = _match_rows_c(self._literals, self._kinds, [text])
            if rows is not NotImplemented:
                return None if rows[0] is None else _Found(rows[0])
        if self.short:
            if self._compiled is None:
                self._compiled = _regex(self._literals, self._kinds)
            return self._compiled.fullmatch(text)
        values, at = [], 0
        for lit, token in zip(self._literals, self._tokens):
            if not text.startswith(lit, at):
                return None
            found = token(text, at + len(lit))
            if found is None:
                return None
            values.append(found.group())
            at = found.end()
        last = self._literals[-1]
        if len(text) - at != len(last) or not text.startswith(last, at):
            return None
        return _Found(tuple(values))


def _rebuilds(literals: tuple[str, ...], rows: list[tuple], texts: list[str]) -> bool:
    """Whether literals and value rows rebuild the texts, compared all at once.

    Each rebuilt text has its text's length (the skipper consumed exactly the literal
    lengths plus the values), so equal concatenations mean equal texts one by one.
    """
    n, k = len(rows), len(literals) - 1
    if k == 0:
        return all(text == literals[0] for text in texts)
    # The window is L0 v L1 v ... v Lk+L0 v L1 ... v Lk: values and literals alternate,
    # so each fills every other piece with one slice assignment.
    pieces: list[str] = [literals[0]] * (2 * n * k + 1)
    pieces[1::2] = chain.from_iterable(rows)
    pieces[2::2] = (literals[1:-1] + (literals[-1] + literals[0],)) * n
    pieces[-1] = literals[-1]
    return "".join(pieces) == "".join(texts)


def bake(literals: tuple[str, ...], values: list[str], fixed: list[bool]) -> tuple[tuple[str, ...], list[str]]:
    """The shape with the fixed values folded into the literals around them."""
    # Pieces joined once: `merged[-1] += ...` copied the growing literal per fixed value,
    # quadratic when a long string is followed by many constants.
    merged: list[list[str]] = [[literals[0]]]
    kept = []
    for lit, val, is_fixed in zip(literals[1:], values, fixed):
        if is_fixed:
            merged[-1] += (val, lit)
        else:
            kept.append(val)
            merged.append([lit])
    return tuple(map("".join, merged)), kept


def _keep_quaternions(values: list[str], fixed: list[bool]) -> None:
    """Unfix x, y, z of a unit quaternion whose w varies: the codec predicts w from them."""
    for j in range(3, len(values)):
        if fixed[j] or not any(fixed[j - 3 : j]):
            continue
        try:
            q = [float(v) for v in values[j - 3 : j + 1]]
        except ValueError:
            continue
        if abs(sum(c * c for c in q) - 1.0) < 1e-6:
            fixed[j - 3 : j] = [False] * 3


def _rows(shape: tuple, texts: list[str]) -> list[tuple | None]:
    """Value rows of texts in a (literals, regex, skipper, kinds) shape; None where one
    misses: `pattern.fullmatch(text).groups()` of each text. From the compiled helper
    when it is installed and the texts are one byte per character, else `_rows_python`."""
    if _match_rows_c is not None:
        rows = _match_rows_c(shape[0], shape[3], texts)
        if rows is not NotImplemented:
            return rows
    return _rows_python(shape, texts)


def _columns(shape: tuple, texts: list[str]) -> list[Sequence[str] | str] | None:
    """The value tokens of texts in a shape by slot, or None if any text misses: `_rows`
    transposed. A string slot gives a sequence of one token per text; a number slot its
    tokens joined by "," in one str (a number token holds no comma: `split(",")` gives
    them back), which is how the encoder parses and checks a number column, or its one
    token when all are the same (`column_tokens` gives them back). The compiled helper
    gives the columns without building rows, or an object per number, in between."""
    if _match_columns_c is not None:
        columns = _match_columns_c(shape[0], shape[3], texts)
        if columns is not NotImplemented:
            return columns
    rows = _rows_python(shape, texts)
    if None in rows:
        return None
    columns = transpose(rows, len(shape[3]))
    return [column if is_string else _number_column(column) for column, is_string in zip(columns, shape[3])]


def _number_column(tokens: Sequence[str]) -> str:
    """A number slot's tokens as `_columns` gives them: the one token if all are the same
    (a constant, found here rather than by joining it n times in the encoder), else all
    joined by ","."""
    if tokens and tokens.count(tokens[0]) == len(tokens):
        return tokens[0]
    return ",".join(tokens)


def column_tokens(column: Sequence[str] | str, n: int) -> Sequence[str]:
    """The n tokens of a value column, whether a sequence or a number slot's str (`_columns`)."""
    if not isinstance(column, str):
        return column
    return column.split(",") if "," in column else [column] * n


def transpose(rows: list[tuple[str, ...]], k: int) -> list[Sequence[str]]:
    """Value rows of k tokens each as k columns."""
    return list(zip(*rows)) if rows else [() for _ in range(k)]


def _rows_python(shape: tuple, texts: list[str]) -> list[tuple | None]:
    """`_rows` with the re module.

    The skipper finds the values without reading the literals; _rebuilds then checks
    them for the whole window at once. Where the regex matches, the skipper matches with
    the same values (both take each value possessively at the same offset), so a text the
    skipper misses is a miss; if the rebuild fails, the regex decides text by text.
    """
    literals, pattern, skipper, _ = shape
    if skipper is None or len(texts) < 2:
        return [None if m is None else m.groups() for m in map(pattern.fullmatch, texts)]
    matches = list(map(skipper.fullmatch, texts))
    if None not in matches:  # the usual case
        rows = list(map(re.Match.groups, matches))
        if _rebuilds(literals, rows, texts):
            return rows
    hits = [i for i, m in enumerate(matches) if m is not None]
    out: list[tuple | None] = [None] * len(texts)
    rows = [matches[i].groups() for i in hits]  # type: ignore[union-attr]
    if hits and _rebuilds(literals, rows, [texts[i] for i in hits]):
        for i, row in zip(hits, rows):
            out[i] = row
        return out
    for i in hits:
        match = pattern.fullmatch(texts[i])
        out[i] = None if match is None else match.groups()
    return out


class ShapeMatcher:
    """Finds the shape of each text; reuses compiled shapes across windows (bounded LRU)."""

    def __init__(self, capacity: int = 256):
        self._capacity = capacity
        self._compiled: OrderedDict[tuple, re.Pattern[str] | None] = OrderedDict()
        self._last: tuple[tuple[str, ...], re.Pattern[str], re.Pattern[str] | None, tuple[bool, ...]] | None = None

    def _pattern(self, key: tuple, literals, values) -> re.Pattern[str] | _LongShape | None:
        pattern = self._compiled.get(key, False)
        if pattern is False:
            pattern = _matcher(literals, values)
            if isinstance(pattern, _LongShape) and not pattern.short:
                return pattern  # cheap to make; the cache would hold its long text
            self._compiled[key] = pattern
            if len(self._compiled) > self._capacity:
                self._compiled.popitem(last=False)
        else:
            self._compiled.move_to_end(key)
        return pattern

    def group_window(self, texts: list[str | None]) -> tuple[list[tuple[tuple, list[int], list]], list[int]]:
        """Groups [(literals, indices, value columns)] of a window, and indices without shape.
        A value column is a sequence of tokens, or a number slot's tokens joined by ","
        or its one token if constant (`_columns`, which the encoder checks with
        `columns.classify_joined`).

        Most values of a robot message never change within a window (covariances, frame
        ids, zero axes). The first pending text and a few probes spread over the window
        show which; those are folded into the literals, so one regex with a handful of
        groups matches the window. Texts it misses start the next round. Any baking is
        exact: the literals are cut from a real text and a match rebuilds its text.
        """
        out: list[tuple[tuple, list[int], list]] = []
        if None in texts:
            unshaped = [i for i, t in enumerate(texts) if t is None]
            pending = [i for i, t in enumerate(texts) if t is not None]
        else:  # the usual window: every text may have a shape
            unshaped, pending = [], list(range(len(texts)))
        for _ in range(_MAX_ROUNDS):
            if not pending:
                return out, unshaped
            # The last window's specialized shape usually fits this one: skip the probes.
            # (So the bytes of a window may depend on the one before; either decodes exactly.)
            last = self._last
            if last is not None and last[1].fullmatch(texts[pending[0]]) and last[1].fullmatch(texts[pending[-1]]):
                shape = last
                self._last = None
            else:
                found = self._specialize(texts, pending)
                if found is None:
                    unshaped.append(pending.pop(0))
                    continue
                if not found:
                    break
                shape = found
            sub = list(texts) if len(pending) == len(texts) else [texts[i] for i in pending]
            columns = _columns(shape, sub)
            if columns is not None:  # the usual case: the whole window has one shape
                out.append((shape[0], pending, columns))
                self._last = shape
                pending = []
                continue
            rows = _rows(shape, sub)
            indices, kept, rest = [], [], []
            for i, row in zip(pending, rows):
                if row is None:
                    rest.append(i)
                else:
                    indices.append(i)
                    kept.append(row)
            out.append((shape[0], indices, transpose(kept, len(shape[3]))))
            pending = rest
        if pending:
            sub = [texts[i] for i in pending]
            groups, rest = self.group(sub)
            for lits, (idx, rows) in groups.items():
                out.append((lits, [pending[j] for j in idx], transpose(rows, len(lits) - 1)))
            unshaped.extend(pending[j] for j in rest)
        return out, sorted(unshaped)

    def _specialize(self, texts: list, pending: list[int]) -> tuple | None:
        """(literals, regex, skipper, kinds) of the first pending text's shape, constants
        baked in (kinds: whether each value slot holds a string).

        None when that text has no shape; () when its shape is too large for a regex.
        """
        split = split_text(texts[pending[0]])
        if split is None:
            return None
        literals, values = split
        kinds = _kinds(values)
        generic = self._pattern((literals, kinds), literals, values)
        if generic is None:
            return ()
        fixed, probed = [True] * len(values), 0
        step = max(1, len(pending) // _PROBES)
        for i in pending[step::step]:
            match = generic.fullmatch(texts[i])
            if match is not None:
                probed += 1
                fixed = [f and a == b for f, a, b in zip(fixed, values, match.groups())]
        if probed == 0 and len(pending) > 1:  # nothing to compare with: bake nothing
            fixed = [False] * len(values)
        _keep_quaternions(values, fixed)
        merged, kept = bake(literals, values, fixed)
        key = (merged, _kinds(kept))
        pattern = self._pattern(key, merged, kept)
        # A _LongShape reads its values itself: a skipper would cost the compile it saves.
        skipper = _skipper(merged, key[1]) if isinstance(pattern, re.Pattern) else None
        return merged, pattern, skipper, key[1]

    def group(self, texts: list[str | None]) -> tuple[dict[tuple, tuple[list[int], list]], list[int]]:
        """Group texts by shape: ({literals: (indices, value rows)}, indices without shape).

        None entries (texts that are not UTF-8) go to the second list.
        """
        groups: dict[tuple, tuple[list[int], list]] = {}
        unshaped: list[int] = []
        recent: list[tuple[tuple, re.Pattern[str], list, list]] = []
        for i, text in enumerate(texts):
            if text is None:
                unshaped.append(i)
                continue
            # Consecutive messages nearly always share a shape: one regex match of the
            # known literals is several times faster than tokenizing from scratch.
            for entry in recent:
                match = entry[1].fullmatch(text)
                if match is not None:
                    entry[2].append(i)
                    entry[3].append(match.groups())
                    break
            else:
                split = split_text(text)
                if split is None:
                    unshaped.append(i)
                    continue
                literals, values = split
                # Equal literals imply an equal number of values (one between each pair).
                indices, rows = groups.setdefault(literals, ([], []))
                indices.append(i)
                rows.append(tuple(values))
                if len(values) > _MAX_MATCHER_SLOTS:
                    continue  # no matcher: not worth the key
                key = (literals, _kinds(values))
                pattern = self._pattern(key, literals, values)
                if pattern is not None and all(key != entry[0] for entry in recent):
                    recent.insert(0, (key, pattern, indices, rows))
                    del recent[4:]
        return groups, unshaped
