"""Per-minute statistics of a run, as JSON texts for the `/cclog/summary` stream.

The paper leaves fleet statistics (distance travelled, ...) to other means; these small
records keep them even though nominal odometry is not stored.
"""

from __future__ import annotations

import json
import math
from collections import deque
from itertools import repeat
from operator import floordiv, itemgetter, ne, sub

import numpy as np

from ..windowcount import SUMMARY_TOPIC

__all__ = ["SUMMARY_TOPIC", "SummaryBuilder"]

NS = 1_000_000_000
MAX_HELD = 1024  # samples update_many holds at most: as fast as more, and a live push that takes them waits < 1 ms


def _ordered_sum(start: float, values: np.ndarray) -> float:
    """start + values[0] + values[1] + ..., added in that order as `update` adds them one
    by one: `cumsum` (`np.add.accumulate`) adds in order, unlike `np.sum`'s pairwise sum,
    and without a Python float and an `add` call a value (issue 14)."""
    return float(np.concatenate(((start,), values)).cumsum()[-1])


class SummaryBuilder:
    """Feed odometry samples in order; get (stamp_ns, json_text) per finished period."""

    def __init__(self, *, period_s: float = 60.0, moving_speed: float = 0.05,
                 gap_s: float = 1.0, accel_baseline_s: float = 0.2):  # fmt: skip
        self.period = int(period_s * NS)
        self.moving_speed = moving_speed
        self.gap = int(gap_s * NS)
        self.baseline = int(accel_baseline_s * NS)
        self.bucket: int | None = None
        self.prev: tuple[int, float, float, float] | None = None
        self.recent: deque[tuple[int, float]] = deque()  # (stamp, speed) for acceleration
        # Samples given to update_many not yet taken: stamps, x, y, speeds, anomalous.
        self._held: tuple[list, ...] = ([], [], [], [], [])
        self._reset()

    def _reset(self) -> None:
        self.stats = {"messages": 0, "distance_m": 0.0, "moving_s": 0.0, "peak_speed": 0.0,
                      "peak_accel": 0.0, "anomalies": 0}  # fmt: skip
        self.first_ns = self.last_ns = None

    def update(self, stamp_ns: int, x: float, y: float, speed: float, anomalous: bool) -> list:
        """One odometry sample; returns the records of periods that ended before it."""
        # Once per odometry message: locals and plain comparisons, no helper calls.
        if self._held[0]:  # samples given to update_many first
            self._settle()
        out = []
        bucket = stamp_ns // self.period
        s = self.stats
        if bucket != self.bucket:
            if self.bucket is not None and s["messages"]:
                out.append(self._record())
                self._reset()
                s = self.stats
            self.bucket = bucket
        s["messages"] += 1
        if anomalous:
            s["anomalies"] += 1
        a = abs(speed)
        if math.isfinite(a) and a > s["peak_speed"]:
            s["peak_speed"] = a
        if self.first_ns is None:
            self.first_ns = stamp_ns
        self.last_ns = stamp_ns
        prev = self.prev
        if prev is not None:
            dt_ns = stamp_ns - prev[0]
            if 0 < dt_ns <= self.gap:
                step = math.hypot(x - prev[1], y - prev[2])
                if math.isfinite(step):
                    s["distance_m"] += step
                if a > self.moving_speed:
                    s["moving_s"] += dt_ns / NS
            else:
                self.recent.clear()
            if dt_ns <= 0:
                return out
        self.prev = (stamp_ns, x, y, speed)
        # Acceleration against the newest sample at least `baseline` older (rate-robust).
        recent = self.recent
        recent.append((stamp_ns, speed))
        bound = stamp_ns - self.baseline
        while len(recent) > 1 and recent[1][0] <= bound:
            recent.popleft()
        t0, v0 = recent[0]
        if t0 <= bound:
            accel = abs(speed - v0) / ((stamp_ns - t0) / NS)
            if math.isfinite(accel) and accel > s["peak_accel"]:
                s["peak_accel"] = accel
        return out

    def update_many(self, stamps: list[int], rows: list, speeds: list[float],
                    anomalous: list[bool]) -> list[tuple[int, tuple[int, str]]]:  # fmt: skip
        """`update` of each sample in turn, its x and y the first two values of its row (of
        floats): (index of the sample, record) of each record it gives, the same records.

        Samples that cannot end a period (of the newest one's) are held, and taken at once
        when one that can comes (or at `flush`, or past MAX_HELD): `_update_steady` of a
        period's samples is 2x faster than `update` of each, of 64 no faster (issue 14)."""
        newest = self._newest_bucket()
        period = self.period
        if stamps and newest is not None and min(stamps) // period == newest == max(stamps) // period:
            # The usual list: all in the newest sample's period (floor division keeps the
            # order), so none ends it; one division each costs ~0.3 us a sample (ints of
            # three digits).
            self._hold(stamps, rows, speeds, anomalous)
            if len(self._held[0]) > MAX_HELD:
                self._settle()
            return []
        buckets = list(map(floordiv, stamps, repeat(self.period, len(stamps))))
        changed = list(map(ne, buckets, [newest, *buckets[:-1]]))
        out: list[tuple[int, tuple[int, str]]] = []
        a = 0
        for k in [k for k, c in enumerate(changed) if c] if True in changed else []:
            self._hold(stamps[a:k], rows[a:k], speeds[a:k], anomalous[a:k])
            self._settle()
            out += [(k, r) for r in self.update(stamps[k], rows[k][0], rows[k][1], speeds[k], anomalous[k])]
            a = k + 1
        self._hold(stamps[a:], rows[a:], speeds[a:], anomalous[a:])
        if len(self._held[0]) > MAX_HELD:
            self._settle()
        return out

    def _newest_bucket(self) -> int | None:
        return self._held[0][-1] // self.period if self._held[0] else self.bucket

    def _hold(self, stamps: list[int], rows: list, speeds: list[float], anomalous: list[bool]) -> None:
        """Hold samples, taking x and y from their rows now: the rows' 13 values are read
        while in cache, and freed with the held odometry, not at the period's end (holding
        the rows until `_settle` made it about 1.7x slower in `record` than alone; issue 14)."""
        xs, ys = list(map(itemgetter(0), rows)), list(map(itemgetter(1), rows))
        for held, new in zip(self._held, (stamps, xs, ys, speeds, anomalous)):
            held += new

    def _settle(self) -> None:
        """`update` of the held samples (of the current period, none ending it)."""
        stamps, xs, ys, speeds, anomalous = self._held
        if not stamps:
            return
        self._held = ([], [], [], [], [])
        t = self._steady(stamps)
        if t is not None:
            self._update_steady(t, xs, ys, speeds, anomalous)
            return
        for k in range(len(stamps)):  # none held now: `update` takes each
            self.update(stamps[k], xs[k], ys[k], speeds[k], anomalous[k])

    def _steady(self, stamps: list[int]) -> np.ndarray | None:
        """The previous sample's stamp and these, as int64, if samples at these stamps
        would all stay in the current period, each after the one before by at most `gap`:
        then `update` does the same with each. Else None.

        Steps up to 2^53 ns only: those are exact as doubles, so that numpy's `dt / NS`
        is Python's (`_update_steady`)."""
        if self.prev is None or self.bucket is None or stamps[-1] // self.period != self.bucket:
            return None
        try:
            t = np.array([self.prev[0], *stamps], dtype=np.int64)
        except OverflowError:  # beyond 64 bits (the store refuses it later): `update` takes each
            return None
        steps = np.diff(t)  # a wrapped difference is negative or beyond the gap: not steady
        return t if steps.min() > 0 and steps.max() <= min(self.gap, 1 << 53) else None

    def _update_steady(self, t: np.ndarray, xs: list[float], ys: list[float], speeds: list[float],
                       anomalous: list[bool]) -> None:  # fmt: skip
        """`update` of each sample of a steady list at once (`t`: the previous sample's
        stamp and theirs, from `_steady`): the same sums, added in the same order
        (`_ordered_sum`), and the same maxima. Differences and divisions are
        numpy's, which round as Python's do; the steps' lengths stay `math.hypot`'s (C's
        `hypot` differs in the last bit)."""
        n = len(xs)
        s, (_, x0, y0, _) = self.stats, self.prev
        s["messages"] += n
        s["anomalies"] += sum(anomalous)
        v = np.array(speeds, dtype=np.float64)
        fast = np.abs(v)
        finite = fast[np.isfinite(fast)]
        s["peak_speed"] = max(s["peak_speed"], float(finite.max()) if len(finite) else 0.0)
        if self.first_ns is None:
            self.first_ns = int(t[1])
        self.last_ns = int(t[-1])
        # The differences as Python floats for `math.hypot` straight from the lists (the
        # same subtractions; no arrays of x and y made and turned back into lists).
        dx, dy = list(map(sub, xs, [x0, *xs[:-1]])), list(map(sub, ys, [y0, *ys[:-1]]))
        steps = np.fromiter(map(math.hypot, dx, dy), np.float64, n)
        s["distance_m"] = _ordered_sum(s["distance_m"], steps[np.isfinite(steps)])
        moving = fast > self.moving_speed
        s["moving_s"] = _ordered_sum(s["moving_s"], np.diff(t)[moving] / NS)
        self._accelerations(t[1:], v)
        self.prev = (self.last_ns, xs[-1], ys[-1], speeds[-1])

    def _accelerations(self, t_new: np.ndarray, v_new: np.ndarray) -> None:
        """`update`'s acceleration of each sample against the newest one at least
        `baseline` older (`recent` and these samples, all in time order), at once."""
        n = len(self.recent)
        t = np.concatenate((np.array([r[0] for r in self.recent], dtype=np.int64), t_new))
        v = np.concatenate((np.array([r[1] for r in self.recent], dtype=np.float64), v_new))
        bound = t[n:] - self.baseline
        base = np.maximum(np.searchsorted(t, bound, side="right") - 1, 0)
        with np.errstate(invalid="ignore"):
            accel = np.abs(v[n:] - v[base]) / ((t[n:] - t[base]) / NS)
        seen = accel[(t[base] <= bound) & np.isfinite(accel)]
        if len(seen):
            self.stats["peak_accel"] = max(self.stats["peak_accel"], float(seen.max()))
        self.recent = deque(zip(t[base[-1] :].tolist(), v[base[-1] :].tolist()))

    def flush(self) -> list:
        """End of input: the record of the unfinished period, if it saw any message."""
        self._settle()
        out = [self._record()] if self.stats["messages"] else []
        self._reset()
        return out

    def _record(self) -> tuple[int, str]:
        start = self.bucket * self.period
        rec = {"start_ns": start, "end_ns": start + self.period, "first_ns": self.first_ns,
               "last_ns": self.last_ns} | {k: (round(v, 6) if isinstance(v, float) else v)
                                           for k, v in self.stats.items()}  # fmt: skip
        return start, json.dumps(rec)
