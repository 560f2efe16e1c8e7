"""Per-minute statistics of a run, as JSON texts for the `/cclog/summary` stream.

The paper leaves fleet statistics (distance travelled, ...) to other means; these small
records keep them even though nominal odometry is not stored.
"""

from __future__ import annotations

import json
import math
from collections import deque
from itertools import repeat
from operator import floordiv, ne

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
        """`update` of each sample in turn, its x and y the first two values of its row."""
        out = []
        for t, row, speed, flag in zip(stamps, rows, speeds, anomalous):
            out += self.update(t, row[0], row[1], speed, flag)
        return out

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
