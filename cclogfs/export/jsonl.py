"""Windows back to JSON Lines, messages of all windows merged into one time order."""

from __future__ import annotations

import heapq
from collections.abc import Iterable, Iterator
from typing import TextIO

from ..jsontext.lines import format_line
from .base import Progress, StoredWindow


def merged_messages(
    windows: Iterable[StoredWindow], start_ns: int | None = None, end_ns: int | None = None
) -> Iterator[tuple[str, int, str]]:
    """(stream, stamp_ns, text) in stamp order, from windows sorted by start_ns.

    Equal stamps keep window order, then message order. A window is opened only once
    the merge reaches its start, so memory holds just the windows that overlap in time.
    A window that overlaps none (most stores: one stream, windows one after another)
    goes out as it is, without the heap: nothing can come between its messages.
    """
    lo = -(1 << 63) if start_ns is None else start_ns
    hi = (1 << 63) if end_ns is None else end_ns
    heap: list[tuple[int, int, int, str, str, Iterator[tuple[int, str]]]] = []
    pending = iter(windows)
    nxt = next(pending, None)
    order = 0
    while heap or nxt is not None:
        while nxt is not None and (not heap or nxt.start_ns <= heap[0][0]):
            after = next(pending, None)
            if not heap and (after is None or after.start_ns > nxt.end_ns):  # alone in time
                for stamp, text in nxt.messages():
                    if stamp > hi:
                        return
                    if stamp >= lo:
                        yield nxt.name, stamp, text
            else:
                it = iter(nxt.messages())
                first = next(it, None)
                if first is not None:
                    heapq.heappush(heap, (first[0], order, 0, nxt.name, first[1], it))
                order += 1
            nxt = after
        if not heap:
            continue
        stamp, o, i, name, text, it = heap[0]
        if stamp > hi:
            break  # windows not yet opened start after `stamp`, so all that is left is later
        if lo <= stamp <= hi:
            yield name, stamp, text
        following = next(it, None)
        if following is None:
            heapq.heappop(heap)
        else:
            heapq.heapreplace(heap, (following[0], o, i + 1, name, following[1], it))


def write_jsonl(
    windows: Iterable[StoredWindow],
    out: TextIO,
    *,
    start_ns: int | None = None,
    end_ns: int | None = None,
    progress: Progress | None = None,
) -> int:
    """Write each message in [start_ns, end_ns] as one JSONL line; returns the count."""
    n = 0
    for name, stamp, text in merged_messages(windows, start_ns, end_ns):
        out.write(format_line(name, stamp, text))
        n += 1
        if progress is not None and n % 1024 == 0:
            progress(1024)
    if progress is not None:
        progress(n % 1024)
    return n
