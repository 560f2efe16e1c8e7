"""JSON Lines logs as a source: a file or standard input, one message per line.

The line format (and its fast and general parsers) is `cclogfs.jsontext.lines`, shared
with the export that writes it. Every line is checked to be valid JSON of the right shape.
"""

from __future__ import annotations

import os
import select
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import BinaryIO, Literal

from ..errors import InvalidInputError, SourceError
from ..jsontext.lines import JsonlLineError, parse_line, split_canonical, split_canonical_bytes
from .base import SourceMessage, topic_filter

OnError = Literal["stop", "skip"]

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
                # 64 KiB reads: with the default 8 KiB, reading lines cost twice as much
                # (a read call every few ~1 KB messages; issue 14).
                self._file: BinaryIO = open(path, "rb", buffering=1 << 16)
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
        split = split_canonical_bytes
        for lineno, raw in enumerate(self._file, 1):
            # Most lines are in the canonical layout, checked whole as JSON on their bytes.
            parts = split(raw)
            if parts is not None:
                if wanted is None or parts[0] in wanted:
                    yield SourceMessage(*parts, "")
                continue
            message = self._slow_line(lineno, raw)
            if message is not None and (wanted is None or message.topic in wanted):
                yield message

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
            return SourceMessage(*parse_line(line))
        except JsonlLineError as err:
            self._bad_line(lineno, str(err))
            return None

    def _bad_line(self, lineno: int, reason: str) -> None:
        err = SourceError(f"{self.name}, line {lineno}: {reason}.")
        if self._on_error == "stop":
            raise err
        self.skipped += 1
        if self._report is not None:
            self._report(err)
