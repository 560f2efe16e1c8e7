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
from itertools import chain

__all__ = ["ShapeMatcher", "split_text"]

_STRING = r'"[^"\\]*(?:\\.[^"\\]*)*"'
_NUMBER = r"[-+.0-9A-Za-z]++"  # numbers, true/false/null, NaN, Infinity
# Possessive quantifiers: a text that does not tokenize fails fast instead of backtracking.
_TOKEN = re.compile(
    r"((?:[\s{}\[\],:]++|" + _STRING + r"\s*+:)*+)(" + _STRING + "|" + _NUMBER + ")", re.S
)
# Shapes with more value slots than this are not compiled into a matcher regex.
_MAX_MATCHER_SLOTS = 4096


def split_text(text: str) -> tuple[tuple[str, ...], list[str]] | None:
    """(literals, values) of a text, or None when the pieces would not rebuild it."""
    pairs = _TOKEN.findall(text)
    used = sum(len(a) + len(b) for a, b in pairs)
    # findall silently skips characters no token matches; then the pieces fall short.
    if "".join(chain.from_iterable(pairs)) != text[:used]:
        return None
    literals = tuple(a for a, _ in pairs) + (text[used:],)
    return literals, [b for _, b in pairs]


def _matcher(literals: tuple[str, ...], values: list[str]) -> re.Pattern[str] | None:
    """A regex that matches exactly the texts of this shape, one group per value."""
    if len(values) > _MAX_MATCHER_SLOTS:
        return None
    parts = []
    for lit, val in zip(literals, values):
        parts.append(re.escape(lit))
        parts.append("(" + (_STRING if val.startswith('"') else _NUMBER) + ")")
    parts.append(re.escape(literals[-1]))
    return re.compile("".join(parts), re.S)


class ShapeMatcher:
    """Finds the shape of each text; reuses compiled shapes across windows (bounded LRU)."""

    def __init__(self, capacity: int = 256):
        self._capacity = capacity
        self._compiled: OrderedDict[tuple, re.Pattern[str] | None] = OrderedDict()

    def _pattern(self, key: tuple, literals, values) -> re.Pattern[str] | None:
        pattern = self._compiled.get(key, False)
        if pattern is False:
            pattern = _matcher(literals, values)
            self._compiled[key] = pattern
            if len(self._compiled) > self._capacity:
                self._compiled.popitem(last=False)
        else:
            self._compiled.move_to_end(key)
        return pattern

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
                key = (literals, tuple(v.startswith('"') for v in values))
                # Equal literals imply an equal number of values (one between each pair).
                indices, rows = groups.setdefault(literals, ([], []))
                indices.append(i)
                rows.append(tuple(values))
                pattern = self._pattern(key, literals, values)
                if pattern is not None and all(key != entry[0] for entry in recent):
                    recent.insert(0, (key, pattern, indices, rows))
                    del recent[4:]
        return groups, unshaped
