"""JSON Lines logs: one `{"topic": .., "stamp_ns": .., "msg": {..}}` object per line.

The `msg` text is kept byte for byte as it appears in the line (its exact slice), so
what goes into the store is what the producer wrote, and `convert` then `cat` gives the
same file back. Every line is still checked to be valid JSON of the right shape.

Speed: lines in the layout `format_line` writes take a fast path (one regular
expression for the head, one `raw_decode` over the message to validate it and find its
end); any other layout (other key order, spacing, escapes in the topic) goes through a
small scanner over the top-level object that uses the json module for every value.
"""

from __future__ import annotations

import functools
import json
import os
import re
import select
import sys
from collections.abc import Callable, Iterable, Iterator
from json.decoder import scanstring
from pathlib import Path
from typing import BinaryIO, Literal

from ..errors import InvalidInputError, SourceError
from ..store.format import MAX_NS, MIN_NS
from ..jsoncheck import json_error
from .base import SourceMessage, topic_filter

OnError = Literal["stop", "skip"]

# The layout format_line() writes; anything else takes the general path.
_FAST_HEAD = re.compile(
    r'\{"topic": "([^"\\\x00-\x1f]+)", "stamp_ns": (0|-?[1-9][0-9]{0,18}), "msg": (?=\{)'
)
_WS = re.compile(r"[ \t\n\r]*")
_DECODER = json.JSONDecoder()
_REQUIRED = ("topic", "stamp_ns", "msg")
_OPTIONAL = ("msgtype",)
_MIN_STAMP, _MAX_STAMP = MIN_NS, MAX_NS  # the store's int64 nanoseconds


# A log has few topics; json.dumps of the name was a tenth of the time to write a line.
_topic_json = functools.lru_cache(maxsize=4096)(json.dumps)


def format_line(topic: str, stamp_ns: int, text: str, msgtype: str = "") -> str:
    """One JSONL line (with its newline) holding `text` unchanged as the `msg` value."""
    if "\n" in text or "\r" in text:
        raise InvalidInputError(
            f"The message on {topic} at {stamp_ns} ns contains a line break, so it cannot "
            "stay byte-exact on one JSON Lines line."
        )
    head = f'{{"topic": {_topic_json(topic)}, "stamp_ns": {int(stamp_ns)}, "msg": '
    if msgtype:
        return f'{head}{text}, "msgtype": {json.dumps(msgtype)}}}\n'
    return f"{head}{text}}}\n"


class JsonlLineError(ValueError):
    """Why one line is not a message; JsonlSource adds the file name and line number."""


def parse_line(line: str) -> tuple[str, int, str, str]:
    """(topic, stamp_ns, msg text, msgtype) of one line without its line ending."""
    m = _FAST_HEAD.match(line)
    if m is not None and line[-1] == "}":
        start = m.end()
        try:
            _, end = _DECODER.raw_decode(line, start)
        except ValueError:
            end = -1
        stamp = int(m.group(2))
        if end == len(line) - 1 and _MIN_STAMP <= stamp <= _MAX_STAMP:
            return m.group(1), stamp, line[start:end], ""
    return _parse_general(line)


def _parse_general(line: str) -> tuple[str, int, str, str]:
    """Any layout of the object: scan its top level, let the json module read each value."""
    try:
        fields = _scan_object(line)
    except ValueError as err:
        # The json module's own message (with column) is the clearest for broken JSON.
        try:
            json.loads(line)
        except ValueError as json_err:
            raise JsonlLineError(f"invalid JSON: {json_err}") from None
        raise JsonlLineError(str(err)) from None
    missing = [k for k in _REQUIRED if k not in fields]
    if missing:
        raise JsonlLineError(f"the object has no {', '.join(repr(k) for k in missing)} key")
    extra = [k for k in fields if k not in _REQUIRED and k not in _OPTIONAL]
    if extra:
        raise JsonlLineError(f"unknown key {extra[0]!r} (expected topic, stamp_ns, msg, msgtype)")
    topic, _, _ = fields["topic"]
    stamp, _, _ = fields["stamp_ns"]
    msg, start, end = fields["msg"]
    msgtype = fields.get("msgtype", ("", 0, 0))[0]
    if not isinstance(topic, str) or not topic:
        raise JsonlLineError("'topic' must be a non-empty string")
    if type(stamp) is not int or not _MIN_STAMP <= stamp <= _MAX_STAMP:
        raise JsonlLineError(f"'stamp_ns' must be a 64-bit integer, not {stamp!r}")
    if not isinstance(msg, dict):
        raise JsonlLineError(f"'msg' must be a JSON object, not {type(msg).__name__}")
    if not isinstance(msgtype, str):
        raise JsonlLineError("'msgtype' must be a string")
    return topic, stamp, line[start:end], msgtype


def _scan_object(line: str) -> dict[str, tuple[object, int, int]]:
    """Top-level keys of a one-object line -> (value, start, end) of each value's text."""
    i = _WS.match(line, 0).end()
    if line[i : i + 1] != "{":
        raise ValueError("a line must hold one JSON object")
    i = _WS.match(line, i + 1).end()
    fields: dict[str, tuple[object, int, int]] = {}
    if line[i : i + 1] == "}":
        i += 1
    else:
        while True:
            if line[i : i + 1] != '"':
                raise ValueError("expected a key")
            key, i = scanstring(line, i + 1)
            i = _WS.match(line, i).end()
            if line[i : i + 1] != ":":
                raise ValueError("expected ':'")
            start = _WS.match(line, i + 1).end()
            value, i = _DECODER.raw_decode(line, start)
            if key in fields:
                raise ValueError(f"duplicate key {key!r}")
            fields[key] = (value, start, i)
            i = _WS.match(line, i).end()
            sep = line[i : i + 1]
            i += 1
            if sep == "}":
                break
            if sep != ",":
                raise ValueError("expected ',' or '}'")
            i = _WS.match(line, i).end()
    if _WS.match(line, i).end() != len(line):
        raise ValueError("text after the object")
    return fields


def _stdin_lines(timeout_s: float = 0.2) -> Iterator[bytes]:
    """Lines of standard input, waiting with select() so the main thread wakes up at least
    every `timeout_s`: a signal the kernel hands to another thread (numpy's BLAS threads
    do not block signals) would otherwise not interrupt a blocked read, and Ctrl-C or
    SIGTERM would not stop an idle live stream."""
    try:
        fd = sys.stdin.fileno()
    except (AttributeError, OSError, ValueError):  # stdin replaced by an in-memory stream
        yield from sys.stdin.buffer
        return
    tail = b""
    while True:
        if not select.select([fd], [], [], timeout_s)[0]:
            continue  # Python runs pending signal handlers here
        chunk = os.read(fd, 1 << 16)
        if not chunk:
            break
        lines = (tail + chunk).split(b"\n")
        tail = lines.pop()
        for line in lines:
            yield line + b"\n"
    if tail:
        yield tail


class JsonlSource:
    """Messages of a JSONL file, or of standard input for the path "-".

    A malformed line is an error naming the file and line (`on_error="stop"`, the
    default), or is skipped, counted in `skipped` and passed to `report`.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        topics: Iterable[str] | None = None,
        on_error: OnError = "stop",
        report: Callable[[SourceError], None] | None = None,
    ) -> None:
        if on_error not in ("stop", "skip"):
            raise InvalidInputError(f"on_error must be 'stop' or 'skip', not {on_error!r}.")
        self._wanted = topic_filter(topics)
        self._on_error = on_error
        self._report = report
        self.skipped = 0
        self._owned = str(path) != "-"
        if self._owned:
            self.name = str(path)
            try:
                self._file: BinaryIO = open(path, "rb")
            except OSError as err:
                raise SourceError(f"Cannot open {self.name}: {err.strerror or err}.") from err
        else:
            self.name = "<stdin>"
            self._file = _stdin_lines()

    def __enter__(self) -> JsonlSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._owned:
            self._file.close()

    def topics(self) -> dict[str, str]:
        """Unknown without reading the whole file, so only the selection (if any) is known."""
        return dict.fromkeys(sorted(self._wanted or ()), "")

    def __iter__(self) -> Iterator[SourceMessage]:
        wanted = self._wanted
        fast_head = _FAST_HEAD.match
        for lineno, raw in enumerate(self._file, 1):
            try:
                line = raw.decode("utf-8")
            except UnicodeDecodeError as err:
                self._bad_line(lineno, f"not UTF-8 text ({err.reason} at byte {err.start})")
                continue
            if line[-1:] == "\n":
                line = line[:-2] if line[-2:-1] == "\r" else line[:-1]
            # Inlined fast path of parse_line(): most lines are in the canonical layout.
            m = fast_head(line)
            if m is not None and line[-1] == "}":
                topic = m.group(1)
                if wanted is not None and topic not in wanted:
                    continue
                start = m.end()
                stamp = int(m.group(2))
                # msg starts with "{" (the regex looks ahead), so line[start:-1] is exactly
                # the msg value when it is one valid value with no whitespace before the
                # final "}"; anything else takes the general path, which reports errors.
                msg = line[start:-1]
                if _MIN_STAMP <= stamp <= _MAX_STAMP and line[-2] not in " \t\r\n" and json_error(msg) is None:
                    yield SourceMessage(topic, stamp, msg, "")
                    continue
            if not line.strip():
                continue
            try:
                topic, stamp, text, msgtype = _parse_general(line)
            except JsonlLineError as err:
                self._bad_line(lineno, str(err))
                continue
            if wanted is None or topic in wanted:
                yield SourceMessage(topic, stamp, text, msgtype)

    def _bad_line(self, lineno: int, reason: str) -> None:
        err = SourceError(f"{self.name}, line {lineno}: {reason}.")
        if self._on_error == "stop":
            raise err
        self.skipped += 1
        if self._report is not None:
            self._report(err)
