"""Per-minute statistics of a run, as JSON texts for the `/cclog/summary` stream.

The paper leaves fleet statistics (distance travelled, ...) to other means; these small
records keep them even though nominal odometry is not stored.
"""

from __future__ import annotations

import json
import math
from collections import deque

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
        out = []
        bucket = stamp_ns // self.period
        if self.bucket is not None and bucket != self.bucket and self.stats["messages"]:
            out.append(self._record())
            self._reset()
        self.bucket = bucket
        s = self.stats
        s["messages"] += 1
        s["anomalies"] += bool(anomalous)
        if math.isfinite(speed):
            s["peak_speed"] = max(s["peak_speed"], abs(speed))
        self.first_ns = stamp_ns if self.first_ns is None else self.first_ns
        self.last_ns = stamp_ns
        if self.prev is not None and 0 < stamp_ns - self.prev[0] <= self.gap:
            dt = (stamp_ns - self.prev[0]) / NS
            step = math.hypot(x - self.prev[1], y - self.prev[2])
            if math.isfinite(step):
                s["distance_m"] += step
            if abs(speed) > self.moving_speed:
                s["moving_s"] += dt
        elif self.prev is not None:
            self.recent.clear()
        if self.prev is None or stamp_ns > self.prev[0]:
            self.prev = (stamp_ns, x, y, speed)
            # Acceleration against the newest sample at least `baseline` older (rate-robust).
            self.recent.append((stamp_ns, speed))
            while len(self.recent) > 1 and self.recent[1][0] <= stamp_ns - self.baseline:
                self.recent.popleft()
            t0, v0 = self.recent[0]
            if stamp_ns - t0 >= self.baseline:
                accel = abs(speed - v0) / ((stamp_ns - t0) / NS)
                if math.isfinite(accel):
                    s["peak_accel"] = max(s["peak_accel"], accel)
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
