"""Logging windows as a user counts them, from the records that hold them.

A window is what a recording's policy made: with smart logging the window around an
anomaly (every topic it logged), with every message kept one chunk of one topic (`--chunk`
messages, fewer when `--window-max-s` cut it). The store may hold one window in several
records, and each such window counts once:

- the parts of a smart window, stored every `--window-max-s` of wall time and every 10,000
  messages of a topic, its latched topics at its close: they share meta `window_id`, and
  each topic's parts are numbered by meta `part` (0, 1, ...; classifier/windows.py);
- a window whose stamps go back, stored as records each in time order
  (`pipeline.store_window`): meta `split` [k, n], put one after the other;
- a record over the 16 MiB record limit, split by the store: each part but the last
  flagged PART, the next record (seq + 1) its continuation (docs/FORMAT.md, "Splitting").

The recorder's own summaries (meta `kind` "summary") are counted apart. `record`'s end
summary and run record, `info`, `export`, `eval` and `plot` all count with this module, so
they say the same number. It knows neither the store nor the classifier: it reads metadata.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["SUMMARY_TOPIC", "Link", "WindowCount", "WindowJoiner", "count_records", "link_of"]

# The stream of the recorder's summaries (classifier.summary writes them), here where they are
# counted apart, so that a reader (`cclog info`) names it without importing the classifier
# and numpy (a quarter second of CPU, most of what info took on an 8 MiB store).
SUMMARY_TOPIC = "/cclog/summary"

# What of a record's meta ties it to other records: (window_id, part, split index, summary).
# Small, so that an export can hold one per record it wrote and count at its end.
Link = tuple[Any, Any, int, bool]


def link_of(meta: Mapping[str, Any] | None) -> Link:
    """The keys of a record's (or a pending window's) meta that say which window it is part of."""
    meta = meta or {}
    split = meta.get("split")
    k = split[0] if isinstance(split, list) and split and isinstance(split[0], int) else 0
    wid = meta.get("window_id")
    # a summary the recorder made: a keep-all recording of a smart store's export keeps that
    # store's summaries as messages that came in (kind "all")
    return (wid if isinstance(wid, str) else None, meta.get("part"), k, meta.get("kind") == "summary")


class WindowJoiner:
    """Numbers the windows of records taken in put (seq) order: `join` says which window a
    record is part of. A smart window's records are never interleaved with another smart
    window's (one is open at a time), so a record joins the newest smart window when it has
    its window_id and a higher part of its topic than that window had (a topic new to it,
    a latched one, joins too); the same id again with part 0 is a new window (the same
    stamps recorded again). Records of other kinds (summaries, every message kept, odometry
    the model could not score) may come between, and change nothing of that."""

    def __init__(self) -> None:
        self.count = 0
        self._prev: tuple[int | None, str, bool, int] | None = None  # seq, stream, PART, window
        self._smart: tuple[str, dict[str, Any], int] | None = None  # window_id, topic -> part, window

    def join(self, stream: str, link: Link, *, seq: int | None = None,
             continues: bool = False) -> tuple[int, str | None, bool]:  # fmt: skip
        """(window number, why the record is part of a window begun before it or None when it
        begins one, whether it is the first of its window in `stream`). Why: "limit" (the
        store split a record over its limit), "split" (the window's stamps went back), "part"
        (a smart window's part). `seq`: the record's (None for a window not yet stored:
        nothing continues it then); `continues`: it is flagged PART (goes on in seq + 1)."""
        prev = self._prev
        if seq is not None and prev is not None and prev[0] == seq - 1 and prev[1] == stream and prev[2]:
            joined = prev[3], "limit", False
        elif seq is not None and prev is not None and prev[0] == seq - 1 and prev[1] == stream and link[2] > 0:
            joined = prev[3], "split", False
        else:
            joined = self._smart_or_new(stream, link)
        self._prev = (seq, stream, continues, joined[0])
        return joined

    def _smart_or_new(self, stream: str, link: Link) -> tuple[int, str | None, bool]:
        wid, part = link[0], link[1]
        smart = self._smart
        if wid is not None and smart is not None and smart[0] == wid:
            parts = smart[1]
            if stream not in parts:
                parts[stream] = part
                return smart[2], "part", True
            last = parts[stream]
            if not (isinstance(part, int) and isinstance(last, int)) or part > last:
                parts[stream] = part
                return smart[2], "part", False
        self.count += 1
        if wid is not None:
            self._smart = (wid, {stream: part}, self.count)
        return self.count, None, True


@dataclass
class WindowCount:
    """Windows, summaries and records of records added in put (seq) order (`add`)."""

    windows: int = 0  # of the messages kept: the recorder's summaries apart
    summaries: int = 0
    records: int = 0  # the records holding `windows`
    streams: dict[str, int] = field(default_factory=dict)  # per stream: windows with a record in it, summaries too
    stream_records: dict[str, int] = field(default_factory=dict)
    # (stream, why) -> records part of a window begun before them (why: `WindowJoiner.join`)
    joined: dict[tuple[str, str], int] = field(default_factory=dict)
    _joiner: WindowJoiner = field(default_factory=WindowJoiner, repr=False, compare=False)

    def add(self, stream: str, link: Link, *, seq: int | None = None, continues: bool = False,
            records: int = 1) -> bool:  # fmt: skip
        """Count one record (`WindowJoiner.join` of it), or a window as the pipeline puts it
        (`records`: how many the store holds it in); True when it starts a window."""
        _, why, here = self._joiner.join(stream, link, seq=seq, continues=continues)
        summary = link[3]
        if why is not None:
            self.joined[stream, why] = self.joined.get((stream, why), 0) + 1
        elif summary:
            self.summaries += 1
        else:
            self.windows += 1
        if not summary:
            self.records += records
        if here:
            self.streams[stream] = self.streams.get(stream, 0) + 1
        self.stream_records[stream] = self.stream_records.get(stream, 0) + records
        return why is None


class CountedTotals:
    """`windows`, `summaries` and `records` of the class's `counted` (a WindowCount), for
    the stats a command prints (`RecordStats`, `ExportStats`), so that each says them alike."""

    counted: WindowCount

    @property
    def windows(self) -> int:
        """Logging windows of the messages kept (a window held in several records counts once)."""
        return self.counted.windows

    @property
    def summaries(self) -> int:
        """The recorder's own summaries (`/cclog/summary`), counted apart from `windows`."""
        return self.counted.summaries

    @property
    def records(self) -> int:
        """The records holding `windows`: a smart window's parts, a window whose stamps go
        back, one the store split over its 16 MiB record limit, each record."""
        return self.counted.records


def count_records(records: Iterable[tuple[int, str, Link, bool]]) -> WindowCount:
    """`WindowCount` of stored records given as (seq, stream, link, flagged PART) in any
    order (an export writes them in time order, a query gives them in start order)."""
    count = WindowCount()
    for seq, stream, link, continues in sorted(records, key=lambda r: r[0]):
        count.add(stream, link, seq=seq, continues=continues)
    return count
