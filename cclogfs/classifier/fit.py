"""Does a robot look like the one a model was trained on? The few statistics a model keeps
of its training odometry (publish rate, speed, turn rate), and the comparison with a new
robot's, so that a model meeting a robot unlike its own says so instead of keeping nothing."""

from __future__ import annotations

import numpy as np

from .features import OdomArrays

__all__ = ["FAR_FACTOR", "NOISE_LAG_S", "compare", "robot_stats", "speed_noise", "standing_still"]

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


def standing_still(trained: dict) -> str | None:
    """Why odometry with these statistics cannot train a model (None: it can): a robot that
    never drives in it. `compare` takes a speed under its floor for standing, so such a
    model finds every robot driving faster than FAR_FACTOR x the floor unlike it, and
    `record --model` refused the robot it was trained on once it drove (a model trained on
    the first 3 s of a simulated run, the robot not yet moving). Said at train time instead."""
    floor = _FLOORS["speed_p95"]
    if trained.get("speed_p95", 0.0) >= floor:
        return None
    return (f"its 95th percentile speed is {trained.get('speed_p95', 0.0):.3g} m/s, under the {floor:g} m/s a model "
            f"needs (below it the robot counts as standing, and `cclog record --model` refuses every robot that "
            f"drives faster than {FAR_FACTOR * floor:g} m/s as unlike it)")  # fmt: skip


# The speed's noise is measured over this lag, not from one message to the next: the change
# per message shrinks with the rate (an interpolated 100 Hz copy of a 12 Hz run changes
# 9x less per message, with the same noise), the change over a fixed time does not.
NOISE_LAG_S = 0.1


def speed_noise(runs: list[OdomArrays]) -> float | None:
    """Robust standard deviation (m/s) of the forward speed's change over NOISE_LAG_S,
    pooled over `runs` (None without such pairs). Wheel odometry: 0.002-0.004 m/s on the
    TUC robot; twist differenced from jittery poses (the slamfail robots): 0.05-0.14 m/s,
    at 12 Hz and resampled to 30 or 100 Hz alike (bench/classifier_long.py)."""
    lag = int(NOISE_LAG_S * 1e9)
    steps = []
    for r in runs:
        t, v = r.stamp_ns, r.raw[:, 7]
        k = np.searchsorted(t, t - lag, side="right") - 1
        # The newest message at least the lag back, and not across a gap (3 lags or more).
        ok = (k >= 0) & (t - t[np.maximum(k, 0)] < 3 * lag)
        d = v[ok] - v[k[ok]]
        steps.append(d[np.isfinite(d)])
    d = np.concatenate(steps) if steps else np.empty(0)
    if not len(d):
        return None
    # A difference of two samples: its spread is sqrt(2) times the speed's own.
    return 1.4826 * float(np.median(np.abs(d))) / np.sqrt(2)


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
