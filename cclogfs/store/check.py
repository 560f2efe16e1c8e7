"""Checks on what users hand to the store, done before anything is written."""

from __future__ import annotations

import operator
from collections.abc import Sequence

from ..errors import InvalidInputError
from .format import MAX_COUNT, MAX_NAME, MAX_NS, MIN_NS
from ..jsontext.check import name_error, text_error


def check_stream_name(name: object) -> bytes:
    """A stream name as UTF-8 bytes. Names are data, never paths: `../x` is fine."""
    if not isinstance(name, str):
        raise InvalidInputError(f"stream name must be a str, got {type(name).__name__}")
    if not name:
        raise InvalidInputError("stream name must not be empty")
    if (why := name_error(name, MAX_NAME)) is not None:
        shown = repr(name) if len(name) <= 80 else f"{name[:60]!r}..."
        raise InvalidInputError(f"stream name {shown} {why}")
    return name.encode("utf-8")


def encode_messages(messages: Sequence[tuple[int, str]], *, check_json: bool = True) -> tuple[list[int], list[str]]:
    """Stamps and texts of a window, every message checked (JSON, UTF-8, time order).

    The texts stay `str` (the codecs take text); `text_error` checks each, without
    encoding it, and `check_json=False` skips only the JSON parse.
    """
    try:
        count = len(messages)
    except TypeError as err:
        raise InvalidInputError("messages must be a sequence of (stamp_ns, json_text) pairs") from err
    if count == 0:
        raise InvalidInputError("a window needs at least one message")
    if count > MAX_COUNT:
        raise InvalidInputError(f"a window holds at most {MAX_COUNT} messages, got {count}")
    if not check_json and (whole := _checked_at_once(messages)) is not None:
        return whole
    stamps: list[int] = []
    texts: list[str] = []
    prev = MIN_NS
    for i, item in enumerate(messages):
        try:
            stamp, text = item
        except (TypeError, ValueError) as err:
            raise InvalidInputError(f"message {i} is not a (stamp_ns, json_text) pair") from err
        if isinstance(stamp, bool):
            raise InvalidInputError(f"message {i}: stamp_ns must be an integer, got a bool")
        try:
            stamp = operator.index(stamp)
        except TypeError as err:
            raise InvalidInputError(f"message {i}: stamp_ns must be an integer, got {type(stamp).__name__}") from err
        if not MIN_NS <= stamp <= MAX_NS:
            raise InvalidInputError(f"message {i}: stamp_ns {stamp} does not fit in 64 bits")
        if stamp < prev:
            raise InvalidInputError(f"message {i}: stamp_ns {stamp} is before the previous message's {prev}; "
                                    "times in a window must not decrease")  # fmt: skip
        prev = stamp
        if (why := text_error(text, check_json=check_json)) is not None:
            raise InvalidInputError(f"message {i} {why}")
        texts.append(text)
        stamps.append(stamp)
    return stamps, texts


def _checked_at_once(messages: Sequence[tuple[int, str]]) -> tuple[list[int], list[str]] | None:
    """`encode_messages` without the JSON parse, by a few checks over the whole window (a
    third of the loop's time, issue 14); None when any check fails, and the loop then
    names the first message that fails it. Stamps must be exactly int here (the loop
    also takes what operator.index takes)."""
    try:
        stamps, texts = map(list, zip(*messages))
    except (TypeError, ValueError):  # not all pairs
        return None
    if set(map(type, stamps)) != {int} or not all(map(operator.le, stamps, stamps[1:])):
        return None
    if stamps[0] < MIN_NS or stamps[-1] > MAX_NS:
        return None
    try:
        if all(map(str.isascii, texts)):  # the usual window: no copy of its texts to check them
            return stamps, texts
        joined = "".join(texts)
    except TypeError:  # not all str
        return None
    if text_error(joined, check_json=False) is not None:  # a lone surrogate in some text
        return None
    return stamps, texts
