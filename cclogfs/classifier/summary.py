"""Per-minute statistics of a run, as JSON texts for the `/cclog/summary` stream.

The paper leaves fleet statistics (distance travelled, ...) to other means; these small
records keep them even though nominal odometry is not stored.
"""

from __future__ import annotations

import json
import math
from collections import deque
from functools import reduce
from itertools import compress, repeat
from operator import add, floordiv, gt, ne, sub, truediv

import numpy as np

__all__ = ["SUMMARY_TOPIC", "SummaryBuilder"]

SUMMARY_TOPIC = "/cclog/summary"
NS = 1_000_000_000


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
        self._reset()

    def _reset(self) -> None:
        self.stats = {"messages": 0, "distance_m": 0.0, "moving_s": 0.0, "peak_speed": 0.0,
                      "peak_accel": 0.0, "anomalies": 0}  # fmt: skip
        self.first_ns = self.last_ns = None

    def update(self, stamp_ns: int, x: float, y: float, speed: float, anomalous: bool) -> list:
        """One odometry sample; returns the records of periods that ended before it."""
        # Once per odometry message: locals and plain comparisons, no helper calls.
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

    def period_starts(self, stamps: list[int]) -> list[int]:
        """Where to cut a list of samples' stamps, in order, so that only a piece's last
        sample can start a new period (end the one before): just after each such sample,
        and at the end."""
        buckets = list(map(floordiv, stamps, repeat(self.period, len(stamps))))
        changed = list(map(ne, buckets, [self.bucket, *buckets[:-1]]))
        cuts = [k + 1 for k, c in enumerate(changed) if c] if True in changed else []
        return cuts if cuts and cuts[-1] == len(stamps) else [*cuts, len(stamps)]

    def update_many(self, stamps: list[int], rows: list, speeds: list[float], anomalous: list[bool]) -> list:
        """`update` of each sample in turn, its x and y the first two values of its row:
        the same records. The samples before the last are taken at once when they are of
        the current period, each within `gap` after the one before (`_update_steady`)."""
        out: list = []
        m = len(stamps) - 1
        if m > 1 and self._steady(stamps[:m]):
            self._update_steady(stamps[:m], rows[:m], speeds[:m], anomalous[:m])
        else:
            m = 0
        for k in range(m, len(stamps)):
            out += self.update(stamps[k], rows[k][0], rows[k][1], speeds[k], anomalous[k])
        return out

    def _steady(self, stamps: list[int]) -> bool:
        """Whether samples at these stamps would all stay in the current period, each
        after the one before by at most `gap`: then `update` does the same with each."""
        if self.prev is None or self.bucket is None or stamps[-1] // self.period != self.bucket:
            return False
        steps = list(map(sub, stamps, [self.prev[0], *stamps[:-1]]))
        return min(steps) > 0 and max(steps) <= self.gap

    def _update_steady(self, stamps: list[int], rows: list, speeds: list[float], anomalous: list[bool]) -> None:
        """`update` of each sample of a steady list (`_steady`) at once: the same sums,
        added in the same order (`reduce`), and the same maxima."""
        s, (t0, x0, y0, _) = self.stats, self.prev
        s["messages"] += len(stamps)
        s["anomalies"] += sum(anomalous)
        fast = list(map(abs, speeds))
        s["peak_speed"] = max(s["peak_speed"], max(filter(math.isfinite, fast), default=0.0))
        if self.first_ns is None:
            self.first_ns = stamps[0]
        self.last_ns = stamps[-1]
        xs, ys = [r[0] for r in rows], [r[1] for r in rows]
        steps = map(math.hypot, map(sub, xs, [x0, *xs[:-1]]), map(sub, ys, [y0, *ys[:-1]]))
        s["distance_m"] = reduce(add, filter(math.isfinite, steps), s["distance_m"])
        dts = map(sub, stamps, [t0, *stamps[:-1]])
        moving = map(gt, fast, repeat(self.moving_speed))
        s["moving_s"] = reduce(add, compress(map(truediv, dts, repeat(NS)), moving), s["moving_s"])
        self._accelerations(stamps, speeds)
        self.prev = (stamps[-1], xs[-1], ys[-1], speeds[-1])

    def _accelerations(self, stamps: list[int], speeds: list[float]) -> None:
        """`update`'s acceleration of each sample against the newest one at least
        `baseline` older (`recent` and these samples, all in time order), at once."""
        n = len(self.recent)
        t = np.array([r[0] for r in self.recent] + stamps, dtype=np.int64)
        v = np.array([r[1] for r in self.recent] + speeds, dtype=np.float64)
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
        out = [self._record()] if self.stats["messages"] else []
        self._reset()
        return out

    def _record(self) -> tuple[int, str]:
        start = self.bucket * self.period
        rec = {"start_ns": start, "end_ns": start + self.period, "first_ns": self.first_ns,
               "last_ns": self.last_ns} | {k: (round(v, 6) if isinstance(v, float) else v)
                                           for k, v in self.stats.items()}  # fmt: skip
        return start, json.dumps(rec)
