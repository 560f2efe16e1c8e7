"""Windows back to JSON Lines, messages of all windows merged into one time order."""

from __future__ import annotations

import heapq
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, TextIO

from ..jsontext.lines import format_lines

if TYPE_CHECKING:  # types only: `cclog cat` need not import the exporters' module (dataclasses, shutil)
    from .base import Progress, StoredWindow


def merged_messages(
    windows: Iterable[StoredWindow], start_ns: int | None = None, end_ns: int | None = None
) -> Iterator[tuple[str, int, str]]:
    """(stream, stamp_ns, text) in stamp order, from windows sorted by start_ns.

    Equal stamps keep window order, then message order (see `merged_runs`).
    """
    for name, run in merged_runs(windows, start_ns, end_ns):
        for stamp, text in run:
            yield name, stamp, text


def continues(window: StoredWindow) -> bool:
    """Whether the window is a part of a split window that goes on (a store `Window`'s
    `continues`; other windows never do)."""
    try:
        return window.continues  # type: ignore[attr-defined]
    except AttributeError:
        return False


# A record holds at most 2**24 messages (FORMAT.md, "Limits"): the message numbers of a split
# window's part j start at j << 24, after those of the parts before it.
PART_SHIFT = 24


def merged_runs(
    windows: Iterable[StoredWindow], start_ns: int | None = None, end_ns: int | None = None
) -> Iterator[tuple[str, list[tuple[int, str]]]]:
    """(stream, [(stamp_ns, text), ...]): runs of one stream, in stamp order when chained.

    Equal stamps keep window order, then message order; the parts of a split window (a
    store `Window` whose `continues` is true goes on in the record after it) keep the order
    of its first part, so they merge as the window whole would. A window is opened only once
    the merge reaches its start, so memory holds just the windows that overlap in time.
    A window that overlaps none (most stores: one stream, windows one after another)
    goes out as one run, without the heap: nothing can come between its messages. Runs
    let the writer format and write a window at once rather than message by message.
    Windows must come sorted by start (`store.query` gives (start, seq) order; seq order is
    not time order where a smart-logged window grew back after a part was stored): a window
    that starts before one given earlier raises ValueError, as messages after its start may
    have gone out already.
    """
    lo = -(1 << 63) if start_ns is None else start_ns
    hi = (1 << 63) if end_ns is None else end_ns
    heap: list[tuple[int, int, int, str, str, Iterator[tuple[int, str]]]] = []
    pending = iter(windows)
    nxt = next(pending, None)
    order = 0
    parts: dict[tuple[str, int], tuple[int, int]] = {}  # (stream, seq) of a next part -> (order, part number)
    opened = -(1 << 63)  # the start of the window opened last
    while heap or nxt is not None:
        while nxt is not None and (not heap or nxt.start_ns <= heap[0][0]):
            if nxt.start_ns < opened:  # messages after its start may have gone out already
                raise ValueError(f"windows must come in start order (as store.query gives them): {nxt.name} "
                                 f"seq {nxt.seq} starts at {nxt.start_ns} ns, before a window given earlier")
            opened = nxt.start_ns
            after = next(pending, None)
            if parts and (nxt.name, nxt.seq) in parts:
                own, part = parts.pop((nxt.name, nxt.seq))
            else:
                own, part, order = order, 0, order + 1
            if continues(nxt):
                parts[nxt.name, nxt.seq + 1] = (own, part + 1)
            if not heap and (after is None or after.start_ns > nxt.end_ns):  # alone in time
                if lo <= nxt.start_ns and nxt.end_ns <= hi:  # wholly inside the range
                    yield nxt.name, list(nxt.messages())
                else:
                    run = []
                    for stamp, text in nxt.messages():
                        if stamp > hi:
                            yield nxt.name, run
                            return
                        if stamp >= lo:
                            run.append((stamp, text))
                    yield nxt.name, run
            else:
                it = iter(nxt.messages())
                first = next(it, None)
                if first is not None:  # a part's messages count on from the part before's
                    heapq.heappush(heap, (first[0], own, part << PART_SHIFT, nxt.name, first[1], it))
            nxt = after
        if not heap:
            continue
        stamp, o, i, name, text, it = heap[0]
        if stamp > hi:
            break  # windows not yet opened start after `stamp`, so all that is left is later
        if lo <= stamp <= hi:
            yield name, [(stamp, text)]
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
    for name, run in merged_runs(windows, start_ns, end_ns):
        if run:
            out.write(format_lines(name, run))
            n += len(run)
            if progress is not None:
                progress(len(run))
    return n
