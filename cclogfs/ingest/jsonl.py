"""JSON Lines logs as a source: a file or standard input, one message per line.

The line format (and its fast and general parsers) is `cclogfs.jsontext.lines`, shared
with the export that writes it. Every line is checked to be valid JSON of the right shape.
"""

from __future__ import annotations

import os
import select
import sys
from collections.abc import Callable, Iterable, Iterator
from operator import itemgetter
from pathlib import Path
from typing import BinaryIO

from ..errors import SourceError
from ..jsontext.check import name_error
from ..jsontext.lines import JsonlLineError, parse_line, split_canonical, split_canonical_bytes
from ..jsontext.rostypes import TypeCheck
from .base import BadMessages, OnError, SourceMessage, topic_filter

# The compiled splitter (cclogfs/ingest/_jsonl_split.c; setup.py builds it where a C
# compiler is): the messages of a list of lines in the canonical layout, None for each
# other line, in a third of the Python path's time (issue 14). Without it, `_split_python`.
try:
    from ._jsonl_split import split_lines as _split_lines_c
except ImportError:  # no C compiler at install: the Python path gives the same messages
    _split_lines_c = None

# Lines read at a time: one read call and one call of the splitter per 256 KiB.
_BATCH_BYTES = 1 << 18


def _split_python(lines: list[bytes], message_type: type = SourceMessage) -> list[SourceMessage | None]:
    """What the compiled splitter gives, in Python: the message of each line in the
    canonical layout (the whole line checked as JSON), None for any other line."""
    out: list[SourceMessage | None] = []
    for raw in lines:
        parts = split_canonical_bytes(raw)
        out.append(None if parts is None else message_type(*parts, ""))
    return out


def split_lines(lines: list[bytes]) -> list[SourceMessage | None]:
    """The message of each line in the canonical layout, None for each line the caller
    must read with `parse_line` (another layout, NaN, a bad line...): compiled when built."""
    if _split_lines_c is not None:
        return _split_lines_c(lines, SourceMessage)
    return _split_python(lines)


def _stdin_batches(timeout_s: float = 0.2) -> Iterator[list[bytes]]:
    """Lines of standard input, a list per read (whatever has arrived, so a live stream
    does not wait for more), waiting with select() so the main thread wakes up at least
    every `timeout_s`: a signal the kernel hands to another thread (numpy's BLAS threads
    do not block signals) would otherwise not interrupt a blocked read, and Ctrl-C or
    SIGTERM would not stop an idle live stream."""
    try:
        fd = sys.stdin.fileno()
    except (AttributeError, OSError, ValueError):  # stdin replaced by an in-memory stream
        for line in sys.stdin.buffer:
            yield [line]
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
        if lines:
            yield [line + b"\n" for line in lines]
    if tail:
        yield [tail]


class JsonlSource:
    """Messages of a JSONL file, or of standard input for the path "-".

    A malformed line is an error naming the file and line (`on_error="stop"`, the
    default), or is skipped, counted in `skipped` and passed to `report`. So is a message
    whose text is over `max_text_bytes` (what a store can hold, when recording into one),
    and one `types` refuses (`jsontext.rostypes.TypeCheck`: a topic of two types, a reserved
    topic, another type than the store's stream has).
    """

    bad_unit = "lines"  # what a summary calls what it skipped; other sources skip messages

    def __init__(
        self,
        path: str | Path,
        *,
        topics: Iterable[str] | None = None,
        on_error: OnError = "stop",
        report: Callable[[SourceError], None] | None = None,
        max_text_bytes: int | None = None,
        types: TypeCheck | None = None,
    ) -> None:
        self._bad = BadMessages(on_error, report)
        self._wanted = topic_filter(topics)
        self._max_text = max_text_bytes
        self._names_ok: set[str] = set()
        # Lines naming a type, or on a reserved topic (`_bad_names`), go the slow way, which checks them.
        self._types = types if types is not None else TypeCheck()
        self._owned = str(path) != "-"
        self._file: BinaryIO | Iterator[list[bytes]]
        if self._owned:
            self.name = str(path)
            try:
                # 64 KiB reads: with the default 8 KiB, reading lines cost twice as much
                # (a read call every few ~1 KB messages; issue 14).
                self._file = open(path, "rb", buffering=1 << 16)
            except OSError as err:
                raise SourceError(f"Cannot open {self.name}: {err.strerror or err}.") from err
        else:
            self.name = "<stdin>"
            self._file = _stdin_batches()

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
        for batch in self.batches():
            yield from batch

    def batches(self) -> Iterator[list[SourceMessage]]:
        """The messages, a list per 256 KiB of lines read (never empty): for a caller that
        handles many messages at once (pipeline.record). The same messages, errors and
        skips as iterating, in the same order."""
        wanted = self._wanted
        lineno = 0
        for lines in self._line_batches():
            # Most lines are in the canonical layout, checked whole as JSON on their bytes.
            messages = split_lines(lines)
            if self._max_text is not None and max(map(len, lines)) > self._max_text:
                # A message's text is a slice of its line: only a longer line can hold one
                # too long to store. Such lines go the slow way, which checks the size.
                messages = [None if len(raw) > self._max_text else m for raw, m in zip(lines, messages)]
            error = None
            if bad := self._bad_names(messages):  # read again line by line, which names the line
                messages = [None if m is not None and m.topic in bad else m for m in messages]
            if None in messages:
                messages, error = self._settle(messages, lines, lineno)
            lineno += len(lines)
            if wanted is not None:
                messages = [m for m in messages if m.topic in wanted]
            if messages:
                yield messages
            if error is not None:  # after the messages before it, as line by line
                raise error

    def _settle(self, messages: list[SourceMessage | None], lines: list[bytes],
                lineno: int) -> tuple[list[SourceMessage], SourceError | None]:  # fmt: skip
        """The batch's messages with the lines the splitter left (None) read in Python, up
        to the first bad line when bad lines stop the read: (messages, its error)."""
        out = []
        for i, message in enumerate(messages):
            if message is None:
                try:
                    message = self._slow_line(lineno + i + 1, lines[i])
                except SourceError as err:
                    return out, err
            if message is not None:
                out.append(message)
        return out, None

    def _bad_names(self, messages: list[SourceMessage | None]) -> set[str]:
        """Topics of the fast path's messages the store would refuse as stream names (a
        C1 control character, over 1024 bytes), or that are reserved (`TypeCheck`): the
        fast layout already keeps out escapes and C0 controls. Each name is checked once per source."""
        new = set(map(itemgetter(0), filter(None, messages))).difference(self._names_ok)  # each message's topic
        reserved = self._types.reserved
        bad = {name for name in new if name in reserved or name_error(name) is not None}
        self._names_ok.update(new - bad)
        return bad

    def _line_batches(self) -> Iterator[list[bytes]]:
        if not self._owned:  # standard input: already a list per read
            yield from self._file
            return
        read = self._file.readlines
        while lines := read(_BATCH_BYTES):
            yield lines

    def _slow_line(self, lineno: int, raw: bytes) -> SourceMessage | None:
        """The message of a line the fast path did not settle: another layout, JSON that
        only `json` reads (NaN...), or an error. None for a blank or skipped line."""
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as err:
            self._bad_line(lineno, f"not UTF-8 text ({err.reason} at byte {err.start})")
            return None
        if line[-1:] == "\n":
            line = line[:-2] if line[-2:-1] == "\r" else line[:-1]
        if not line.strip():
            return None
        parts = split_canonical(line)
        if parts is not None and self._wanted is not None and parts[0] not in self._wanted:
            return None  # in the canonical layout, a topic not wanted is skipped unchecked
        try:
            message = SourceMessage(*parse_line(line))
        except JsonlLineError as err:
            self._bad_line(lineno, str(err))
            return None
        if (why := name_error(message.topic)) is not None:
            # Here, not when the store refuses its window: that loses the window's good
            # messages, and names no line.
            self._bad_line(lineno, f"'topic' {why}")
            return None
        if (self._wanted is None or message.topic in self._wanted) and \
                (why := self._types.mismatch(message.topic, message.msgtype)) is not None:  # fmt: skip
            self._bad_line(lineno, why)
            return None
        if self._max_text is not None and len(raw) > self._max_text:
            size = len(message.text.encode())
            wanted = self._wanted is None or message.topic in self._wanted
            if size > self._max_text and wanted:
                self._bad_line(lineno, f"the message is {size} bytes of JSON, over the {self._max_text} bytes "
                               "one record of a store holds")  # fmt: skip
                return None
        return message

    @property
    def skipped(self) -> int:
        """Bad lines skipped (on_error="skip")."""
        return self._bad.skipped

    def _bad_line(self, lineno: int, reason: str) -> None:
        self._bad(SourceError(f"{self.name}, line {lineno}: {reason}."))
