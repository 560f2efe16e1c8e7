"""What an exporter consumes: windows as the store's `query()` returns them."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from typing import Any, Protocol

# Called with the number of messages just written, for progress bars.
Progress = Callable[[int], None]


class StoredWindow(Protocol):
    """One stored window of one stream: the read shape of the store's `Window`.

    A Protocol, not the store's class: an exporter needs only this shape, so export does
    not depend on the storage engine and any iterable of such windows (a query, a test's
    fake, a filter over a query) can be exported.
    """

    name: str
    seq: int
    start_ns: int
    end_ns: int
    meta: dict[str, Any]

    def messages(self) -> Iterator[tuple[int, str]]:
        """(stamp_ns, exact JSON text) of each message, in time order."""
        ...


@dataclasses.dataclass
class ExportStats:
    """What an export wrote."""

    windows: int = 0
    messages: int = 0
    streams: set[str] = dataclasses.field(default_factory=set)
    files: list[str] = dataclasses.field(default_factory=list)
