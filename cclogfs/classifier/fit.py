"""Does a robot look like the one a model was trained on? The few statistics a model keeps
of its training odometry (publish rate, speed, turn rate), and the comparison with a new
robot's, so that a model meeting a robot unlike its own says so instead of keeping nothing."""

from __future__ import annotations

import numpy as np

from .features import OdomArrays

__all__ = ["FAR_FACTOR", "compare", "robot_stats"]

# A statistic this many times larger or smaller than in training is "far outside": the
# features are per-second quantities calibrated on the training robot, so a 4x faster robot
# or a 4x slower publisher moves most vectors out of the region the model learned.
FAR_FACTOR = 4.0
# Below these a robot is standing still: the ratio of two near-zeros says nothing.
_FLOORS = {"rate_hz": 0.1, "speed_p95": 0.05, "turn_p95": 0.05}
_WHAT = {"rate_hz": ("publish rate", "Hz"), "speed_p95": ("95th percentile speed", "m/s"),
         "turn_p95": ("95th percentile turn rate", "rad/s")}  # fmt: skip


def robot_stats(runs: list[OdomArrays]) -> dict:
    """Median publish rate and 95th percentile planar speed and turn rate over `runs`."""
    dts = [np.diff(r.stamp_ns) / 1e9 for r in runs if len(r.stamp_ns) > 1]
    dt = np.concatenate(dts) if dts else np.empty(0)
    dt = dt[dt > 0]
    raw = np.concatenate([r.raw for r in runs]) if runs else np.empty((0, 13))
    speed = np.hypot(raw[:, 7], raw[:, 8])
    turn = np.abs(raw[:, 12])
    ok = np.isfinite(speed) & np.isfinite(turn)
    return {
        "messages": int(len(raw)),
        "rate_hz": float(1.0 / np.median(dt)) if len(dt) else 0.0,
        "speed_p95": float(np.percentile(speed[ok], 95)) if ok.any() else 0.0,
        "turn_p95": float(np.percentile(turn[ok], 95)) if ok.any() else 0.0,
    }


def compare(trained: dict | None, seen: dict) -> list[str]:
    """One sentence per statistic of `seen` far outside `trained` (none for an old model
    file that kept no statistics)."""
    if not trained:
        return []
    out = []
    for key, floor in _FLOORS.items():
        a, b = max(float(trained.get(key, 0.0)), floor), max(float(seen.get(key, 0.0)), floor)
        if max(a, b) / min(a, b) > FAR_FACTOR:
            what, unit = _WHAT[key]
            out.append(f"{what} {seen.get(key, 0.0):.3g} {unit} against {trained.get(key, 0.0):.3g} {unit} in training")
    return out
