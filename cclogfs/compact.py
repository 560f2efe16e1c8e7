"""Compaction and aging: old windows rewritten at lower fidelity, the oldest dropped to
fit a storage budget.

This module wires `aging` (what happens to a window's JSON) to the store (how records are
rewritten and segments dropped, crash-safely; see docs/FORMAT.md). Order of work:

1. Windows of the chosen streams that end before the cutoff are aged with the policy,
   unless one of their passes already used it (so a nightly run is idempotent, and
   policies that take turns settle) or it changes nothing. Each aged window's metadata
   gains a pass in `meta["aged"]`: the rules, the max rate, and the message count
   before. Errors add up over passes.
2. While the store's files (manifest, segments, indexes) are over the budget, the
   oldest sealed segment is dropped (retention). The active segment is never dropped;
   if the budget cannot be met without it, the report says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from typing import Sequence

from .aging import Policy
from .errors import InvalidInputError
from .compaction import Replacement
from .format import RecordFlag
from .index import merge_stream_stats
from .store import Store, Window

__all__ = ["DEFAULT_EXCLUDE", "CompactReport", "Upkeep", "compact"]

# The smart-logging summary answers "how far did the robot drive this year"; it is tiny,
# so it stays exact unless a stream pattern names it.
DEFAULT_EXCLUDE = ("/cclog/*",)


@dataclass
class CompactReport:
    """What a compaction did, per stream, and whether the budget was met."""

    # stream -> windows aged, messages before/after, stored bytes before/after (of the
    # aged windows' segments: windows copied unchanged count on both sides)
    aged: dict[str, dict[str, int]] = field(default_factory=dict)
    dropped: dict[str, dict[str, int]] = field(default_factory=dict)  # stream_stats sums
    segments_dropped: int = 0
    disk_before: int = 0
    disk_after: int = 0
    budget: int | None = None

    @property
    def over_budget(self) -> bool:
        return self.budget is not None and self.disk_after > self.budget

    def to_dict(self) -> dict:
        return {"aged": self.aged, "dropped": self.dropped, "segments_dropped": self.segments_dropped,
                "disk_before": self.disk_before, "disk_after": self.disk_after, "budget": self.budget,
                "over_budget": self.over_budget}  # fmt: skip


def selected(name: str, streams: Sequence[str] | None) -> bool:
    """Whether aging applies to a stream: it matches a pattern, or by default is not excluded."""
    if streams:
        return any(fnmatchcase(name, p) for p in streams)
    return not any(fnmatchcase(name, p) for p in DEFAULT_EXCLUDE)


def compact(
    store: Store,
    *,
    policy: Policy | None = None,
    before_ns: int | None = None,
    older_than_ns: int | None = None,
    streams: Sequence[str] | None = None,
    budget: int | None = None,
    segments: Sequence[int] | None = None,
    seal: bool = True,
) -> CompactReport:
    """Age windows with `policy`, then drop the oldest sealed segments while the store holds
    more than `budget` bytes.

    Which windows age: those ending before `before_ns`, or ending more than `older_than_ns`
    before the last window of their own stream (streams may run on different clocks: sim
    time, log time), or all of them when neither is given; only in the sealed segments
    starting at `segments` (first seqs; default all). With `seal`, the segment being
    written is sealed first when it holds windows to age.
    """
    report = CompactReport(disk_before=store.data_bytes(), budget=budget)
    # The segment being written is never dropped, not even once sealed here for aging.
    keep_from = store.active.first_seq if store.active is not None else None
    if policy is not None:
        _age(store, policy, _cutoffs(store, before_ns, older_than_ns), streams, report, segments, seal)
    if budget is not None:
        while store.data_bytes() > budget:
            if keep_from is not None and store.sealed and store.sealed[0].first_seq >= keep_from:
                break
            gone = store.drop_oldest()
            if gone is None:
                break
            report.segments_dropped += 1
            merge_stream_stats(report.dropped, gone.streams)
    report.disk_after = store.data_bytes()
    return report


def passes_of(window: Window) -> list:
    """The aging passes a window went through, oldest first ([] for a byte-exact window).
    Each is a dict as `compact` writes them; another writer's statement is kept as one
    opaque pass."""
    aged = window.aged  # only set with the AGED record flag
    if aged is None:
        return []
    return list(aged) if isinstance(aged, list) else [aged]


def _cutoffs(store: Store, before_ns: int | None, older_than_ns: int | None) -> dict[str, int] | None:
    """Per stream, the end time before which its windows age (None: every window ages).

    "Newest" is the end of the stream's last window in log order, not its largest stamp:
    after a simulator restart (its clock back at 0) or one wild stamp, the largest stamp
    would make the fresh windows look old.
    """
    if before_ns is None and older_than_ns is None:
        return None
    last: dict[str, tuple[int, int]] = {}  # stream -> (seq, end_ns) of its last window
    if older_than_ns is not None:
        for w in store.query():
            if w.seq > last.get(w.name, (-1, 0))[0]:
                last[w.name] = (w.seq, w.end_ns)
    out = {}
    for name in store.streams():
        limits = [before_ns] if before_ns is not None else []
        if older_than_ns is not None:
            limits.append(last[name][1] - older_than_ns)
        out[name] = min(limits)
    return out


def _candidates(store: Store, cutoff: dict[str, int] | None, streams, segments: Sequence[int] | None) -> list[int]:
    """Sealed segments that may hold a window to age: one of the selected streams starts in
    them before its cutoff (the manifest's statistics say so without reading a record)."""
    wanted = None if segments is None else set(segments)
    out = []
    for info in store.manifest["segments"]:
        if wanted is not None and info["first_seq"] not in wanted:
            continue
        if any(selected(name, streams) and (cutoff is None or st["start_ns"] < cutoff.get(name, st["start_ns"]))
               for name, st in info["streams"].items()):  # fmt: skip
            out.append(info["first_seq"])
    return out


def _age(store: Store, policy: Policy, cutoff: dict[str, int] | None, streams, report: CompactReport,
         segments: Sequence[int] | None, seal: bool) -> None:  # fmt: skip
    desc = policy.describe()
    counts: dict[str, list[int]] = {}

    def due(window: Window) -> bool:
        if not selected(window.name, streams):
            return False
        if cutoff is not None and window.end_ns >= cutoff.get(window.name, window.end_ns):
            return False
        # Already aged by this policy (in any pass: policies that take turns settle after
        # one pass each): a nightly run rewrites nothing.
        return not any(isinstance(p, dict) and {k: p.get(k) for k in desc} == desc for p in passes_of(window))

    def rewrite(window: Window) -> Replacement | None:
        if not due(window):
            return None
        messages = list(window.messages())
        aged = policy.age(messages)
        if aged == messages:
            return None  # nothing moved: no new pass to record
        meta = dict(window.meta)
        meta["aged"] = passes_of(window) + [{**desc, "messages_before": len(messages)}]
        c = counts.setdefault(window.name, [0, 0, 0])
        c[0] += 1
        c[1] += len(messages)
        c[2] += len(aged)
        return Replacement(aged, meta, flags=RecordFlag.AGED)

    # Windows in the active segment can be rewritten only once it is sealed.
    active = store.active
    if seal and active is not None and any(w.seq >= active.first_seq and due(w) for w in store.query()):
        store.seal()
        if segments is not None:
            segments = [*segments, active.first_seq]
    before: dict[str, dict[str, int]] = {}
    after: dict[str, dict[str, int]] = {}
    # One segment per commit: the disk holds both generations of only one segment at a time.
    for first_seq in _candidates(store, cutoff, streams, segments):
        done = store.rewrite(rewrite, segments=[first_seq])
        merge_stream_stats(before, done.before)
        merge_stream_stats(after, done.after)
    for name, (windows, n_before, n_after) in counts.items():
        report.aged[name] = {
            "windows": windows, "messages_before": n_before, "messages_after": n_after,
            "bytes_before": before[name]["stored_bytes"], "bytes_after": after[name]["stored_bytes"],
        }  # fmt: skip


class Upkeep:
    """Retention run by the recorder itself, which holds the store's only writer lock.

    `after_put(store)` is one comparison until a segment is sealed; then, while the store
    is over `budget`, the oldest sealed segments are dropped (each a manifest rename and an
    unlink: milliseconds). Segments are at most 1/8 of the budget (`store_options`), so the
    store stays within about that much over it.

    Aging is not done here: rewriting a segment reads and re-encodes all of it (seconds to
    minutes for 64 MiB) while the recorder would wait. Age with `cclog compact` while the
    robot is not recording (docked, charging).
    """

    def __init__(self, *, budget: int):
        if budget <= 0:
            raise InvalidInputError(f"A storage budget must be a positive number of bytes, got {budget}.")
        self.budget = budget
        self.sealed_upto = -1  # end seq of the newest sealed segment at the last run
        self.runs = 0
        self.dropped_segments = 0
        self.last: CompactReport | None = None

    def store_options(self) -> dict:
        """Options for open_store: retention drops whole segments, so small ones keep the
        store close to its budget."""
        return {"segment_bytes": max(64 << 10, min(64 << 20, self.budget // 8))}

    @property
    def over_budget(self) -> bool:
        return self.last is not None and self.last.over_budget

    def after_put(self, store: Store) -> CompactReport | None:
        # A new sealed segment moves this (the count may not change: drops remove others).
        upto = store.sealed[-1].next_seq if store.sealed else -1
        if upto == self.sealed_upto:
            return None
        report = compact(store, budget=self.budget)
        self.sealed_upto = store.sealed[-1].next_seq if store.sealed else -1
        self.runs += 1
        self.dropped_segments += report.segments_dropped
        self.last = report
        return report
