"""Upkeep while recording: retention right after a segment is sealed, aging in a
background thread (see `Upkeep`)."""

from __future__ import annotations

import signal
import threading
from typing import Sequence

from .._signals import signals_deferred
from ..errors import CorruptionError, InvalidInputError, StoreFailedError
from ..store import SealedSegment, Store
from .job import (CompactReport, Stopped, age_segments, candidate_segments, compact, room_to_age, selected,
                  unmatched_rules)
from .policy import Policy, Rule

__all__ = ["Upkeep"]

MAX_ERRORS = 20  # background errors kept for the report
MIN_SEGMENT_BYTES = 4096  # the smallest segment_bytes open_store takes
# Below this a recording's segments (1/8 of the budget) would be larger than 1/8 of it, and
# retention, which drops sealed segments whole, could keep none of the run.
MIN_BUDGET = 8 * MIN_SEGMENT_BYTES


def _cutoffs_sealed(store: Store, older_than_ns: int) -> dict[str, int]:
    """Per stream, `older_than_ns` before the end of its newest sealed segment's windows
    (from the manifest: nothing is read)."""
    out: dict[str, int] = {}
    for seg in reversed(store.sealed_segments()):
        for name, st in seg.streams.items():
            out.setdefault(name, st["end_ns"] - older_than_ns)
    return out


def _by_first_seq(store: Store) -> dict[int, SealedSegment]:
    return {seg.first_seq: seg for seg in store.sealed_segments()}


class Upkeep:
    """Compaction run by the recorder, which holds the store's only writer lock.

    `after_put(store)` is one comparison until a segment is sealed. Then:
    - with only a `budget`, the oldest sealed segments are dropped while the store's files
      are over it, right there (each drop is a manifest rename and an unlink);
    - with an aging `policy` (and `older_than_ns`), a background thread does the work:
      aging one sealed segment per commit, oldest first, each followed by retention, so
      that what aging saved keeps older data (retention first when the disk has no room
      for a rewrite). The rewrite plans
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
        self.active_seen: int | None = None  # the active segment's first seq at the last put
        self.runs = self.dropped_segments = self.aged_windows = 0
        self.damage_dropped: list[dict] = []  # named damage of the segments dropped (`say_dropped_damage`)
        self.bytes_before = self.bytes_after = 0  # stored bytes of the segments aged, before and after
        self.messages_thinned = 0  # messages aging left out (max rate)
        self.errors: list[str] = []  # what failed in the background (the first MAX_ERRORS)
        self.done: set[int] = set()  # first seqs of segments with nothing left to age
        self.seen: dict[int, dict] = {}  # first seq -> the cutoffs it was last aged at
        self.broken: set[int] = set()  # segments that failed their checks: not retried
        # Rules matching no number field of the data (`check_rules`): a misspelt field, which
        # the other rules would round for good. Once found, nothing ages for the rest of the run.
        self.unmatched: list[Rule] = []
        self._rules_checked = False
        self._wake, self._stop, self._exited = threading.Event(), threading.Event(), threading.Event()
        self._finish = False
        self._thread: threading.Thread | None = None

    def store_options(self) -> dict:
        """Options for open_store: retention drops whole segments, so small ones keep the
        store close to its budget."""
        if self.budget is None:
            return {}
        # The floor is the store's smallest segment (4 KiB), not 64 KiB: under 512 KiB a
        # 64 KiB segment was over the budget's eighth, and a budget of 48 KiB dropped every
        # sealed segment of the run whole (0 of 8,860 messages kept).
        return {"segment_bytes": max(MIN_SEGMENT_BYTES, min(64 << 20, self.budget // 8))}

    def after_put(self, store: Store) -> None:
        # Sealing starts a new active segment: until then, one comparison per put.
        active = store.active_first_seq
        if active == self.active_seen:
            return
        self.active_seen = active
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

    def check_rules(self, store: Store) -> None:
        """Refuse the policy's rules that match no number field of the first window of any
        stream aging applies to (`unmatched_rules`, as `compact` checks): run before anything
        ages, and by the recorder at the end of its input. Fields are known only once data
        is stored, and a rule may name a stream that comes later, so the check waits for the
        first aging, the last moment before a misspelt rule does harm. Refused rules go to
        `unmatched` and aging stops; retention and the recording go on."""
        if self._rules_checked or self.policy is None or not self.policy.rules:
            return
        names = [name for name in store.streams() if selected(name, self.streams)]
        if not names:
            return  # no data to check against yet
        self.unmatched = unmatched_rules(store, self.policy, streams=self.streams)
        self._rules_checked = True

    def _retain(self, store: Store, *, pending: bool = True) -> int:
        """Drop the oldest segments while over the budget; how many were dropped. With
        `pending`, what aging is yet to save on the segments due counts as saved (at the
        ratio it saved so far): a drop is for good, and aging the backlog first would
        have kept that segment (issue 16 item 9). A full disk asks without it."""
        self.runs += 1
        if self.budget is None:
            return 0
        slack = self._pending_savings(store) if pending and self.policy is not None else 0
        return self.count_drops(compact(store, budget=self.budget + slack))

    def count_drops(self, report: CompactReport) -> int:
        """Add what a compaction dropped to this upkeep's counts; how many segments."""
        self.dropped_segments += report.segments_dropped
        self.damage_dropped += report.damage_dropped
        return report.segments_dropped

    def _pending_savings(self, store: Store) -> int:
        """Bytes aging will save on the segments due and not yet aged, at the ratio it
        achieved on what it aged so far (nothing before it aged anything)."""
        if not self.bytes_before:
            return 0
        ratio = min(1.0, self.bytes_after / self.bytes_before)
        cutoff = _cutoffs_sealed(store, self.older_than_ns)
        due = sum(seg.size for seg in self._due(store, cutoff))
        return int(due * (1 - ratio))

    def _due(self, store: Store, cutoff: dict[str, int]) -> list[SealedSegment]:
        """Sealed segments with windows to age at `cutoff`, oldest first."""
        segs = _by_first_seq(store)
        out = []
        for first_seq in candidate_segments(store, cutoff, self.streams, None):
            seg = segs.get(first_seq)  # None: sealed since `segs` was read; the next pass has it
            if seg is None or first_seq in self.done or first_seq in self.broken:
                continue  # nothing left to age in it (or not readable)
            if self.seen.get(first_seq) != self._mine(seg, cutoff):  # else aged at these cutoffs already
                out.append(seg)
        return out

    def _mine(self, seg: SealedSegment, cutoff: dict[str, int]) -> dict:
        return {name: cutoff.get(name) for name in seg.streams if selected(name, self.streams)}

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
                # Aging first: what it saves keeps older segments within the budget, which
                # retention would otherwise have dropped already (issue 16 item 9). A disk
                # with no room for a rewrite gets retention first.
                if not room_to_age(store):
                    self._retain(store, pending=False)
                self._age_all(store)
                self._retain(store)
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
        """Age every sealed segment with windows due, one commit each, newest first: were
        aging to fall behind the recording, the segments retention will keep are aged
        first. When the disk has no room for the next rewrite, retention runs first. A
        segment is read again only once the cutoffs of its streams have moved."""
        cutoff = _cutoffs_sealed(store, self.older_than_ns)
        due = self._due(store, cutoff)
        if due:
            self.check_rules(store)
        if self.unmatched:
            return
        for seg in reversed(due):
            if self._stop.is_set():
                return
            if not room_to_age(store) and self._retain(store, pending=False):
                if seg.first_seq not in _by_first_seq(store):
                    continue  # dropped to make room
            report = CompactReport()
            try:
                age_segments(store, self.policy, cutoff, self.streams, report, segments=[seg.first_seq], seal=False,
                             stop=self._stop)  # fmt: skip
            except CorruptionError as err:
                self.broken.add(seg.first_seq)  # reported once; `cclog fsck` says more
                self._error(err)
                continue
            for a in report.aged.values():
                self.aged_windows += a["windows"]
                self.bytes_before += a["bytes_before"]
                self.bytes_after += a["bytes_after"]
                self.messages_thinned += a["messages_before"] - a["messages_after"]
            mine = self._mine(seg, cutoff)
            self.seen[seg.first_seq] = mine
            if all(seg.streams[name]["end_ns"] < limit for name, limit in mine.items() if limit is not None):
                self.done.add(seg.first_seq)  # every selected window was old enough
