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

import signal
import threading
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from typing import Sequence

from ._signals import signals_deferred
from .aging import Policy
from .errors import CorruptionError, InvalidInputError, StoreFailedError
from .store import RecordFlag, Replacement, Store, Window, file_bytes, merge_stream_stats

__all__ = ["DEFAULT_EXCLUDE", "CompactReport", "Upkeep", "compact", "preview"]

# The smart-logging summary answers "how far did the robot drive this year"; it is tiny,
# so it stays exact unless a stream pattern names it.
DEFAULT_EXCLUDE = ("/cclog/*",)
MAX_ERRORS = 20  # background errors kept for the report


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
    keep_from = store.active_first_seq
    if policy is not None:
        _age(store, policy, _cutoffs(store, before_ns, older_than_ns), streams, report, segments=segments, seal=seal)
    if budget is not None:
        while store.data_bytes() > budget:
            sealed = store.sealed_segments()
            if keep_from is not None and sealed and sealed[0].first_seq >= keep_from:
                break
            gone = store.drop_oldest()
            if gone is None:
                break
            report.segments_dropped += 1
            merge_stream_stats(report.dropped, gone.streams)
    report.disk_after = store.data_bytes()
    return report


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
    and the segments retention would drop were aging to save nothing."""
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
        active = store.active_first_seq
        for seg in store.sealed_segments():
            if size <= budget or (active is not None and seg.first_seq >= active):
                break
            size -= file_bytes(store, seg, seg.gen)
            report.segments_dropped += 1
            merge_stream_stats(report.dropped, seg.streams)
    report.disk_after = size
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
    for seg in store.sealed_segments():
        if wanted is not None and seg.first_seq not in wanted:
            continue
        if any(selected(name, streams) and (cutoff is None or st["start_ns"] < cutoff.get(name, st["start_ns"]))
               for name, st in seg.streams.items()):  # fmt: skip
            out.append(seg.first_seq)
    return out


class Stopped(BaseException):
    """Raised inside a rewrite when its Upkeep is closing: nothing is committed."""


def _age(store: Store, policy: Policy, cutoff: dict[str, int] | None, streams, report: CompactReport,
         segments: Sequence[int] | None, seal: bool, stop: threading.Event | None = None) -> None:  # fmt: skip
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
    for first_seq in _candidates(store, cutoff, streams, segments):
        done = store.rewrite(rewrite, segments=[first_seq])
        merge_stream_stats(before, done.before)
        merge_stream_stats(after, done.after)
    for name, (windows, n_before, n_after) in counts.items():
        report.aged[name] = {
            "windows": windows, "messages_before": n_before, "messages_after": n_after,
            "bytes_before": before[name]["stored_bytes"], "bytes_after": after[name]["stored_bytes"],
        }  # fmt: skip


def _cutoffs_sealed(store: Store, older_than_ns: int) -> dict[str, int]:
    """Per stream, `older_than_ns` before the end of its newest sealed segment's windows
    (from the manifest: nothing is read)."""
    out: dict[str, int] = {}
    for seg in reversed(store.sealed_segments()):
        for name, st in seg.streams.items():
            out.setdefault(name, st["end_ns"] - older_than_ns)
    return out


class Upkeep:
    """Compaction run by the recorder, which holds the store's only writer lock.

    `after_put(store)` is one comparison until a segment is sealed. Then:
    - with only a `budget`, the oldest sealed segments are dropped while the store's files
      are over it, right there (each drop is a manifest rename and an unlink);
    - with an aging `policy` (and `older_than_ns`), a background thread does the work:
      retention, then aging one sealed segment per commit, oldest first. The rewrite plans
      without the store's lock, so recording goes on (sharing the interpreter); only the
      commit waits for it. The thread alone drops or rewrites, so the two never race.
    Segments are at most 1/8 of the budget (`store_options`), so the store stays within
    about that much over it, plus what seals while a segment is being aged. `close()` stops
    the thread (an unfinished rewrite commits nothing) and must come before the store's.
    """

    def __init__(self, *, budget: int | None = None, policy: Policy | None = None,
                 older_than_ns: int | None = None, streams: Sequence[str] | None = None):  # fmt: skip
        if budget is not None and budget <= 0:
            raise InvalidInputError(f"A storage budget must be a positive number of bytes, got {budget}.")
        if policy is not None and (older_than_ns is None or older_than_ns < 0):
            raise InvalidInputError("Aging while recording needs an age (older_than_ns >= 0): else every "
                                    "window would age as soon as its segment is sealed.")  # fmt: skip
        if budget is None and policy is None:
            raise InvalidInputError("An Upkeep needs a budget, an aging policy, or both.")
        self.budget, self.policy, self.older_than_ns, self.streams = budget, policy, older_than_ns, streams
        self.sealed_upto = -1  # end seq of the newest sealed segment at the last run
        self.runs = self.dropped_segments = self.aged_windows = 0
        self.errors: list[str] = []  # what failed in the background (the first MAX_ERRORS)
        self.done: set[int] = set()  # first seqs of segments with nothing left to age
        self.seen: dict[int, dict] = {}  # first seq -> the cutoffs it was last aged at
        self.broken: set[int] = set()  # segments that failed their checks: not retried
        self._wake, self._stop, self._exited = threading.Event(), threading.Event(), threading.Event()
        self._finish = False
        self._thread: threading.Thread | None = None

    def store_options(self) -> dict:
        """Options for open_store: retention drops whole segments, so small ones keep the
        store close to its budget."""
        if self.budget is None:
            return {}
        return {"segment_bytes": max(64 << 10, min(64 << 20, self.budget // 8))}

    def after_put(self, store: Store) -> None:
        # A new sealed segment moves this (the count may not change: drops remove others).
        sealed = store.sealed_segments()
        upto = sealed[-1].end_seq if sealed else -1
        if upto == self.sealed_upto:
            return
        self.sealed_upto = upto
        if self.policy is None:
            self._retain(store)
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._work, args=(store,), name="cclogfs-upkeep", daemon=True)
            self._thread.start()
        self._wake.set()

    def close(self, *, finish: bool = False) -> None:
        """Stop the background thread, if any: at once (an unfinished rewrite commits
        nothing), or with `finish` once it has aged what is due. Call it before closing the
        store; an interrupt while waiting for it stops the thread at once, then goes on."""
        if finish:
            self._finish = True
        else:
            self._stop.set()
        self._wake.set()
        if self._thread is None:
            return
        try:
            self._exited.wait()
        except BaseException:
            # Not Thread.join: once interrupted, a second join may return while the thread
            # still runs (CPython 3.11), and the store would be closed under it.
            self._stop.set()
            with signals_deferred():
                self._exited.wait()
            raise

    def _retain(self, store: Store) -> int:
        """Drop the oldest segments while over the budget; how many were dropped."""
        self.runs += 1
        if self.budget is None:
            return 0
        dropped = compact(store, budget=self.budget).segments_dropped
        self.dropped_segments += dropped
        return dropped

    def _work(self, store: Store) -> None:
        try:
            self._loop(store)
        finally:
            self._exited.set()

    def _loop(self, store: Store) -> None:
        # Process signals belong to the main thread (see Store._flush_loop).
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        while True:
            self._wake.wait()
            self._wake.clear()
            if self._stop.is_set():
                return
            try:
                self._retain(store)
                self._age_all(store)
            except Stopped:
                return
            except StoreFailedError as err:  # the recorder sees it at its next put
                self._error(err)
                return
            except Exception as err:  # noqa: BLE001 - recording must go on; say what failed
                self._error(err)
            if self._finish and not self._wake.is_set():  # nothing sealed meanwhile: done
                return

    def _error(self, err: BaseException) -> None:
        if len(self.errors) < MAX_ERRORS:
            self.errors.append(f"{type(err).__name__}: {err}")

    def _age_all(self, store: Store) -> None:
        """Age every sealed segment with windows due, oldest first, one commit each. A
        segment is read again only once the cutoffs of its streams have moved."""
        cutoff = _cutoffs_sealed(store, self.older_than_ns)
        infos = {s.first_seq: s for s in store.sealed_segments()}  # again after each drop
        for first_seq in _candidates(store, cutoff, self.streams, None):
            if self._stop.is_set():
                return
            info = infos.get(first_seq)
            if info is None or first_seq in self.done or first_seq in self.broken:
                continue
            mine = {name: cutoff.get(name) for name in info.streams if selected(name, self.streams)}
            if self.seen.get(first_seq) == mine:
                continue  # aged at these cutoffs already: nothing new is due
            report = CompactReport()
            try:
                _age(store, self.policy, cutoff, self.streams, report, segments=[first_seq], seal=False,
                     stop=self._stop)  # fmt: skip
            except CorruptionError as err:
                self.broken.add(first_seq)  # reported once; `cclog fsck` says more
                self._error(err)
                continue
            self.aged_windows += sum(a["windows"] for a in report.aged.values())
            self.seen[first_seq] = mine
            if all(info.streams[name]["end_ns"] < limit for name, limit in mine.items() if limit is not None):
                self.done.add(first_seq)  # every selected window was old enough
            if self._retain(store):
                infos = {s.first_seq: s for s in store.sealed_segments()}
