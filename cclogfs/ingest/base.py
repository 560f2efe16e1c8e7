"""What every log source yields, and the Protocol a source class implements."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Literal, NamedTuple, Protocol, runtime_checkable

from ..errors import InvalidInputError, SourceError

OnError = Literal["stop", "skip"]


class SourceMessage(NamedTuple):
    """One message: `text` is its rosbridge JSON, `stamp_ns` its time in nanoseconds."""

    topic: str
    stamp_ns: int
    text: str
    msgtype: str


@runtime_checkable
class Source(Protocol):
    """A readable log (bag, MCAP, JSONL); use as a context manager, iterate for messages."""

    name: str

    def __init__(self, path: str, *, topics: Iterable[str] | None = None) -> None: ...

    def __enter__(self) -> Source: ...

    def __exit__(self, *exc: object) -> None: ...

    def __iter__(self) -> Iterator[SourceMessage]: ...

    def topics(self) -> dict[str, str]:
        """Topic -> message type of what the source holds ("" when not known up front)."""
        ...


class BadMessages:
    """What a source does with a bad message (line): raise its error (on_error="stop"), or
    skip it, counting it in `skipped` and passing the error to `report` ("skip")."""

    def __init__(self, on_error: OnError = "stop", report: Callable[[SourceError], None] | None = None) -> None:
        if on_error not in ("stop", "skip"):
            raise InvalidInputError(f"on_error must be 'stop' or 'skip', not {on_error!r}.")
        self.on_error, self.report = on_error, report
        self.skipped = 0

    def __call__(self, err: SourceError) -> None:
        if self.on_error == "stop":
            raise err
        self.skipped += 1
        if self.report is not None:
            self.report(err)


CLOCKS = ("log", "header")


def check_clock(clock: str) -> str:
    """The clock a source stamps messages with: "log" (receive time, the default) or
    "header" (header.stamp, else the log time); docs/JSON.md states the rule."""
    if clock not in CLOCKS:
        raise InvalidInputError(f"Clock {clock!r} is not known; use log (receive time) or header (header.stamp).")
    return clock


def topic_filter(topics: Iterable[str] | None) -> frozenset[str] | None:
    """The selected topics as a set, None meaning all; an empty selection is an error."""
    if topics is None:
        return None
    wanted = frozenset(topics)
    if not wanted:
        raise InvalidInputError("The topic selection is empty; pass None to read every topic.")
    return wanted
