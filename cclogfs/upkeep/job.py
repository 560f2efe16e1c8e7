"""The compaction job: old windows rewritten at lower fidelity, the oldest dropped to fit
a storage budget.

This module wires the aging `Policy` (what happens to a window's JSON) to the store (how
records are rewritten and segments dropped, crash-safely; see docs/FORMAT.md). Order of
work:

1. Windows of the chosen streams that end before the cutoff are aged with the policy,
   unless one of their passes already used it (so a nightly run is idempotent, and
   policies that take turns settle) or it changes nothing. Each aged window's metadata
   gains a pass in `meta["aged"]`: the rules, the max rate, and the message count
   before. Errors add up over passes.
2. While the store's files (manifest, segments, indexes) are over the budget, the
   oldest sealed segment is dropped (retention). The active segment is never dropped;
   if the budget cannot be met without it, the report says so.

Aging comes first so that what it saves keeps older data within the budget; when the
disk has no room for a rewrite (a full disk), retention comes first and makes it.

It sees the store only through its public API (`sealed_segments()`, `active_first_seq`,
`rewrite`, `drop_oldest`, ...): the manifest's per-segment statistics say which segments
may hold windows due without reading a record.
"""

from __future__ import annotations

import errno
import threading
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from typing import Sequence

from ..errors import InvalidInputError, StoreError
from ..runs import RUNS_STREAM
from ..store import RecordFlag, Replacement, Store, Window, file_bytes, merge_stream_stats
from .policy import Policy

__all__ = ["DEFAULT_EXCLUDE", "CompactReport", "Stopped", "age_segments", "candidate_segments", "check_budget", "compact",
           "no_space", "passes_of", "preview", "room_to_age", "selected", "smallest_budget",
           "unmatched_rules"]  # fmt: skip

# The smart-logging summary answers "how far did the robot drive this year"; it is tiny,
# so it stays exact unless a stream pattern names it.
DEFAULT_EXCLUDE = ("/cclog/*",)
# The recording runs are the store's history (what was recorded, from which source: the
# check that refuses a source twice reads them), a few hundred bytes a run: retention keeps
# them, carrying them out of each segment it drops (FORMAT.md, "Compaction and retention").
KEPT_STREAMS = (RUNS_STREAM,)


@dataclass
class CompactReport:
    """What a compaction did, per stream, and whether the budget was met."""

    # stream -> windows aged, messages before/after, stored bytes before/after (of the
    # aged windows' segments: windows copied unchanged count on both sides)
    aged: dict[str, dict[str, int]] = field(default_factory=dict)
    dropped: dict[str, dict[str, int]] = field(default_factory=dict)  # stream_stats sums
    segments_dropped: int = 0
    damage_dropped: list[dict] = field(default_factory=list)  # named damage of the dropped segments
    disk_before: int = 0
    disk_after: int = 0
    budget: int | None = None

    @property
    def over_budget(self) -> bool:
        return self.budget is not None and self.disk_after > self.budget

    def to_dict(self) -> dict:
        return {"aged": self.aged, "dropped": self.dropped, "segments_dropped": self.segments_dropped,
                "damage_dropped": self.damage_dropped,
                "disk_before": self.disk_before, "disk_after": self.disk_after, "budget": self.budget,
                "over_budget": self.over_budget}  # fmt: skip


def selected(name: str, streams: Sequence[str] | None) -> bool:
    """Whether aging applies to a stream: it matches a pattern, or by default is not excluded.
    Never to KEPT_STREAMS, even named: a run's fingerprint and counts must stay exact (a
    --dry-run listed the runs as to be aged, the active segment was sealed for them)."""
    if name in KEPT_STREAMS:
        return False
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
    keep_from = store.active_first_seq
    # Aging first lets retention keep the older data it shrank; on a disk too full for a
    # rewrite (both generations of a segment at once) retention runs first to make room.
    age_first = budget is None or room_to_age(store)
    if policy is not None and age_first:
        try:
            age_segments(store, policy, _cutoffs(store, before_ns, older_than_ns), streams, report,
                         segments=segments, seal=seal)  # fmt: skip
        except StoreError as err:
            if budget is None or not no_space(err):
                raise
            age_first = False  # the disk filled meanwhile (nothing committed): retention, then again
    if budget is not None:
        _retain(store, budget, keep_from, report)
    if policy is not None and not age_first:
        age_segments(store, policy, _cutoffs(store, before_ns, older_than_ns), streams, report,
                     segments=segments, seal=seal)  # fmt: skip
    report.disk_after = store.data_bytes()
    return report


def room_to_age(store: Store) -> bool:
    """Whether the disk has room for a rewrite: the new generation of the largest sealed
    segment (and its index) beside the old one."""
    need = max((file_bytes(store, seg, seg.gen) for seg in store.sealed_segments()), default=0)
    return store.free_bytes() >= need


def no_space(err: BaseException) -> bool:
    """Whether a store error was a full disk (ENOSPC or a quota), which retention relieves."""
    while err is not None:
        if isinstance(err, OSError) and err.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        err = err.__cause__
    return False


def _retain(store: Store, budget: int, keep_from: int | None, report: CompactReport) -> None:
    """Drop the oldest sealed segments while the store is over `budget`, none from
    `keep_from` (a seq) on."""
    while store.data_bytes() > budget:
        sealed = store.sealed_segments()
        if keep_from is not None and sealed and sealed[0].first_seq >= keep_from:
            break
        gone = store.drop_oldest(carry=KEPT_STREAMS)
        if gone is None:
            break
        report.segments_dropped += 1
        merge_stream_stats(report.dropped, gone.streams)
        report.damage_dropped += gone.damaged


def check_budget(text: str, budget: int, smallest: int, why: str, what: str) -> None:
    """Refuse, before anything is written or dropped, a budget (`text` as given) under the
    `smallest` that keeps anything: retention drops whole segments, so under it every one
    goes (`why` says why, `what` what would go). `cclog record` and `cclog compact` ask this."""
    if budget < smallest:
        raise InvalidInputError(f"--budget {text} is too small: {why}, so retention would drop all of {what}; "
                                f"give --budget {_ceil_kib(smallest)} or more.")  # fmt: skip


def smallest_budget(store: Store) -> tuple[int, list]:
    """The smallest budget retention meets keeping the newest sealed segment (the store's
    files less every older one), and the sealed segments under it would drop: all of them
    (none when the store has no sealed segment, whose budget is then its size)."""
    keep_from = store.active_first_seq
    sealed = [seg for seg in store.sealed_segments() if keep_from is None or seg.first_seq < keep_from]
    older = sum(file_bytes(store, seg, seg.gen) for seg in sealed[:-1])
    return store.data_bytes() - older, sealed


def _ceil_kib(n: int) -> str:
    """`n` bytes as a --budget at least as large: whole KiB (MiB from 10 MiB on)."""
    return f"{-(-n // 1024)}KiB" if n < 10 << 20 else f"{-(-n // (1 << 20))}MiB"


def _due(window: Window, desc: dict, cutoff: dict[str, int] | None, streams) -> bool:
    """Whether `window` is to be aged by the policy described by `desc`."""
    if not selected(window.name, streams):
        return False
    if cutoff is not None and window.end_ns >= cutoff.get(window.name, window.end_ns):
        return False
    # Already aged by this policy (in any pass: policies that take turns settle after one
    # pass each): a nightly run rewrites nothing.
    return not any(isinstance(p, dict) and {k: p.get(k) for k in desc} == desc for p in passes_of(window))


def preview(
    store: Store,
    *,
    policy: Policy | None = None,
    before_ns: int | None = None,
    older_than_ns: int | None = None,
    streams: Sequence[str] | None = None,
    budget: int | None = None,
) -> CompactReport:
    """What `compact` with the same arguments would do, changing nothing (works on a
    read-only store): the windows it would age, with their messages and stored bytes now,
    and the segments retention would drop were aging to save nothing, with the damage named
    in them (which goes with them, as `compact` reports)."""
    report = CompactReport(disk_before=store.data_bytes(), budget=budget)
    if policy is not None:
        desc, cutoff = policy.describe(), _cutoffs(store, before_ns, older_than_ns)
        for w in store.query():
            if _due(w, desc, cutoff, streams):
                a = report.aged.setdefault(w.name, {"windows": 0, "messages_before": 0, "bytes_before": 0})
                a["windows"] += 1
                a["messages_before"] += w.count
                a["bytes_before"] += w.stored_bytes
    size = report.disk_before
    if budget is not None:
        keep_from = store.active_first_seq
        for seg in store.sealed_segments():
            if size <= budget or (keep_from is not None and seg.first_seq >= keep_from):
                break
            size -= file_bytes(store, seg, seg.gen)
            report.segments_dropped += 1
            merge_stream_stats(report.dropped, {k: v for k, v in seg.streams.items() if k not in KEPT_STREAMS})
            report.damage_dropped += seg.damage_dropped()
    report.disk_after = size
    return report


def unmatched_rules(store: Store, policy: Policy, *, before_ns: int | None = None, older_than_ns: int | None = None,
                    streams: Sequence[str] | None = None) -> list:  # fmt: skip
    """The policy's rules that match no number field of the first window due in each stream
    (`Policy.unmatched`), to refuse before aging changes anything for good. One window per
    stream: a stream's messages share their type, and reading every window would cost a
    second pass over all that ages."""
    desc, cutoff = policy.describe(), _cutoffs(store, before_ns, older_than_ns)
    seen: set[str] = set()
    texts: list[str] = []
    for w in store.query():
        if w.name not in seen and _due(w, desc, cutoff, streams):
            seen.add(w.name)
            texts.extend(text for _, text in w.messages())
    return policy.unmatched(texts) if texts else []


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


def candidate_segments(store: Store, cutoff: dict[str, int] | None, streams,
                       segments: Sequence[int] | None) -> list[int]:  # fmt: skip
    """Sealed segments that may hold a window to age: one of the selected streams starts in
    them before its cutoff (the manifest's statistics say so without reading a record)."""
    wanted = None if segments is None else set(segments)
    out = []
    for seg in store.sealed_segments():
        if wanted is not None and seg.first_seq not in wanted:
            continue
        if any(selected(name, streams) and (cutoff is None or st["start_ns"] < cutoff.get(name, st["start_ns"]))
               for name, st in seg.streams.items()):  # fmt: skip
            out.append(seg.first_seq)
    return out


class Stopped(BaseException):
    """Raised inside a rewrite when its Upkeep is closing: nothing is committed."""


def age_segments(store: Store, policy: Policy, cutoff: dict[str, int] | None, streams, report: CompactReport,
                 segments: Sequence[int] | None, seal: bool, stop: threading.Event | None = None) -> None:  # fmt: skip
    """Age the windows due in the sealed segments starting at `segments` (default all), one
    segment per commit, adding what was done to `report`. With `seal`, the segment being
    written is sealed first when it holds windows due. `stop` set: raise Stopped in the
    next rewrite, which then commits nothing."""
    desc = policy.describe()
    counts: dict[str, list[int]] = {}

    def due(window: Window) -> bool:
        return _due(window, desc, cutoff, streams)

    def rewrite(window: Window) -> Replacement | None:
        if stop is not None and stop.is_set():
            raise Stopped
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
    active = store.active_first_seq
    if seal and active is not None and any(w.seq >= active and due(w) for w in store.query()):
        store.seal()
        if segments is not None:
            segments = [*segments, active]
    before: dict[str, dict[str, int]] = {}
    after: dict[str, dict[str, int]] = {}
    # One segment per commit: the disk holds both generations of only one segment at a time.
    for first_seq in candidate_segments(store, cutoff, streams, segments):
        done = store.rewrite(rewrite, segments=[first_seq])
        merge_stream_stats(before, done.before)
        merge_stream_stats(after, done.after)
    for name, (windows, n_before, n_after) in counts.items():
        report.aged[name] = {
            "windows": windows, "messages_before": n_before, "messages_after": n_after,
            "bytes_before": before[name]["stored_bytes"], "bytes_after": after[name]["stored_bytes"],
        }  # fmt: skip
