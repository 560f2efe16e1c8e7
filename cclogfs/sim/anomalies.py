"""Anomaly kinds, their scheduling, and the disturbance each one injects.

Two families:
- *motion* anomalies change what the robot does: they override the velocity command
  (mode 1: new targets and acceleration limits) or the velocity itself (mode 2:
  `v = a + b*v`, for the hard stop of a collision) inside the closed loop;
- *sensor* anomalies change what odometry reports: extra wheel travel (slip) or pose
  increments that the twist does not explain (localization trouble).

Severity 1.0 is the default strength, below 1 milder; each kind's effect grows with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidInputError

__all__ = ["KINDS", "KIND_GROUPS", "Event", "schedule_events"]

# kind -> group (what the paper calls it); the order is the index in label arrays (1-based).
KIND_GROUPS: dict[str, str] = {
    "acceleration": "sudden_acceleration",
    "twist": "sudden_twist",
    "oscillation": "planning_failure",
    "stuck": "planning_failure",
    "spin": "planning_failure",
    "back_and_forth": "planning_failure",
    "pose_jump": "localization",
    "pose_twist_mismatch": "localization",
    "collision": "collision",
    "wheel_slip": "wheel_slip",
}
KINDS: tuple[str, ...] = tuple(KIND_GROUPS)
SENSOR_KINDS = frozenset({"pose_jump", "pose_twist_mismatch", "wheel_slip"})

# Duration range in seconds for each kind, drawn uniformly.
_DURATION_S: dict[str, tuple[float, float]] = {
    "acceleration": (1.0, 2.5),
    "twist": (0.6, 1.6),
    "oscillation": (4.0, 12.0),
    "stuck": (6.0, 20.0),
    "spin": (5.0, 12.0),
    "back_and_forth": (4.0, 10.0),
    "pose_jump": (0.5, 4.0),
    "pose_twist_mismatch": (2.0, 8.0),
    "collision": (1.0, 3.0),
    "wheel_slip": (0.5, 3.0),
}
_WARMUP_S = 5.0  # the robot leaves its first room before anything goes wrong
_TAIL_S = 2.0
_GAP_S = 4.0  # quiet time between two anomalies, so each shows as its own event


@dataclass(frozen=True)
class Event:
    """One injected anomaly: [start_ns, end_ns) in header-stamp time."""

    kind: str
    start_ns: int
    end_ns: int
    severity: float
    start_s: float  # seconds since the run's first sample
    end_s: float
    seed: int  # draws the kind's shape parameters

    @property
    def group(self) -> str:
        return KIND_GROUPS[self.kind]

    def to_dict(self) -> dict:
        """The labels-file form."""
        return {
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "kind": self.kind,
            "group": self.group,
            "severity": round(self.severity, 6),
        }


def schedule_events(
    rng: np.random.Generator,
    *,
    duration_s: float,
    start_ns: int,
    count: int,
    kinds: tuple[str, ...],
    severity: tuple[float, float],
    strict: bool,
) -> list[Event]:
    """Place `count` non-overlapping events at random; `strict=False` drops what does not fit."""
    if count == 0:
        return []
    reps = -(-count // len(kinds))
    seq = [str(k) for k in rng.permutation(np.tile(np.array(kinds), reps))[:count]]
    lengths = np.array([rng.uniform(*_DURATION_S[k]) for k in seq])
    span = duration_s - _WARMUP_S - _TAIL_S
    free = span - lengths.sum() - _GAP_S * (count - 1)
    if free < 0:
        if strict:
            need = lengths.sum() + _GAP_S * (count - 1) + _WARMUP_S + _TAIL_S
            raise InvalidInputError(
                f"{count} anomalies need about {need:.0f} s but the run lasts {duration_s:g} s; "
                "ask for fewer anomalies or a longer duration."
            )
        while count and free < 0:
            count -= 1
            seq, lengths = seq[:count], lengths[:count]
            free = span - lengths.sum() - _GAP_S * max(count - 1, 0)
        if count == 0:
            return []
    slack = np.sort(rng.uniform(0.0, free, count))
    events = []
    t = _WARMUP_S
    prev_slack = 0.0
    for kind, length, s in zip(seq, lengths, slack):
        t += s - prev_slack
        prev_slack = s
        sev = float(rng.uniform(*severity))
        t0, t1 = t, t + float(length)
        events.append(
            Event(
                kind=kind,
                start_ns=start_ns + round(t0 * 1e9),
                end_ns=start_ns + round(t1 * 1e9),
                severity=sev,
                start_s=t0,
                end_s=t1,
                seed=int(rng.integers(0, 2**31)),
            )
        )
        t = t1 + _GAP_S
    return events


@dataclass
class Overrides:
    """Per-step overrides of the closed loop at the internal rate (NaN: keep controller value)."""

    mode: np.ndarray  # int8: 0 none, 1 command, 2 force
    a: np.ndarray  # mode 1: v target; mode 2: v offset
    b: np.ndarray  # mode 1: w target; mode 2: v gain
    c: np.ndarray  # mode 1: linear accel limit; mode 2: w offset
    d: np.ndarray  # mode 1: angular accel limit; mode 2: w gain

    @classmethod
    def empty(cls, n: int) -> Overrides:
        nan = np.full(n, np.nan)
        return cls(np.zeros(n, np.int8), nan.copy(), nan.copy(), nan.copy(), nan.copy())


def motion_overrides(events: list[Event], n: int, dt: float, a_max: float) -> Overrides:
    """The command/force overrides of all motion anomalies on an n-step internal grid."""
    ov = Overrides.empty(n)
    for ev in events:
        if ev.kind in SENSOR_KINDS:
            continue
        i0 = max(0, math.ceil(ev.start_s / dt - 1e-9))
        i1 = min(n, math.ceil(ev.end_s / dt - 1e-9))
        if i1 <= i0:
            continue
        t = (np.arange(i0, i1) - i0) * dt
        _MOTION[ev.kind](ov, slice(i0, i1), t, ev.end_s - ev.start_s, ev.severity,
                         np.random.default_rng(ev.seed), dt, a_max)
    return ov


def _acceleration(ov, sl, t, length, sev, rng, dt, a_max):
    # surge far harder than the nominal limit, then brake as hard
    ov.mode[sl] = 1
    surge = t < length * rng.uniform(0.35, 0.55)
    ov.a[sl] = np.where(surge, 1.0 + 0.6 * sev, 0.0)
    ov.c[sl] = a_max * (1.0 + 4.0 * sev)


def _twist(ov, sl, t, length, sev, rng, dt, a_max):
    ov.mode[sl] = 1
    sign = rng.choice([-1.0, 1.0])
    turning = t < length * rng.uniform(0.5, 0.7)
    ov.b[sl] = np.where(turning, sign * (1.5 + 2.0 * sev), 0.0)
    ov.d[sl] = 4.0 + 8.0 * sev


def _oscillation(ov, sl, t, length, sev, rng, dt, a_max):
    # the planner flips between two headings: yaw rate swings while the robot creeps
    ov.mode[sl] = 1
    f = rng.uniform(0.4, 0.9)
    ov.a[sl] = rng.uniform(0.05, 0.2)
    amp = 0.5 + 0.9 * sev
    # the swing fades out before the window ends, so the robot leaves it within limits
    fade = np.clip((length - t) / 0.8, 0.0, 1.0)
    ov.b[sl] = amp * fade * np.sin(2 * np.pi * f * t)
    # enough angular acceleration to follow the swing; a slew-limited square wave would
    # settle into a triangle around whatever offset it started from
    ov.d[sl] = 1.5 * 2 * np.pi * f * amp


def _stuck(ov, sl, t, length, sev, rng, dt, a_max):
    # stopped, with small recovery nudges every couple of seconds
    ov.mode[sl] = 1
    period = rng.uniform(2.0, 3.5)
    phase = np.mod(t, period)
    nudge = (phase > period - 0.6) & (t > 1.0)
    k = np.floor(t / period)
    sign = np.where(np.mod(k, 2) == 0, 1.0, -1.0)
    ov.a[sl] = np.where(nudge, 0.06 * sev * sign, 0.0)
    ov.b[sl] = np.where(nudge, -0.5 * sev * sign, 0.0)


def _spin(ov, sl, t, length, sev, rng, dt, a_max):
    ov.mode[sl] = 1
    ov.a[sl] = 0.0
    ov.b[sl] = rng.choice([-1.0, 1.0]) * (0.7 + 0.5 * sev)
    ov.d[sl] = 1.5 + sev


def _back_and_forth(ov, sl, t, length, sev, rng, dt, a_max):
    ov.mode[sl] = 1
    half = rng.uniform(0.9, 1.5)
    sign = np.where(np.mod(np.floor(t / half), 2) == 0, 1.0, -1.0)
    ov.a[sl] = sign * (0.15 + 0.3 * sev)
    ov.b[sl] = 0.0
    ov.c[sl] = a_max * 1.5


def _collision(ov, sl, t, length, sev, rng, dt, a_max):
    # hit: speed gone in a few tens of ms; bounce back and yaw kick; then standing still
    hit, bounce = 0.06, 0.06 + rng.uniform(0.25, 0.4)
    mode = np.where(t < bounce, 2, 1).astype(np.int8)
    ov.mode[sl] = mode
    decay = math.exp(-dt / 0.015)
    in_hit = t < hit
    # recoil: up within 50 ms of the impact, then dying away
    u = t - hit
    rise = np.sin(0.5 * np.pi * np.clip(u / 0.05, 0.0, 1.0))
    fall = np.cos(0.5 * np.pi * np.clip((u - 0.05) / (bounce - hit - 0.05), 0.0, 1.0)) ** 2
    shape = np.where(u < 0.05, rise, fall)
    kick = rng.choice([-1.0, 1.0]) * (0.3 + 0.9 * sev)
    ov.a[sl] = np.where(mode == 2, np.where(in_hit, 0.0, -(0.1 + 0.25 * sev) * shape), 0.0)
    ov.b[sl] = np.where(mode == 2, np.where(in_hit, decay, 0.0), np.nan)
    ov.c[sl] = np.where(mode == 2, np.where(in_hit, 0.0, kick * shape), a_max)
    ov.d[sl] = np.where(mode == 2, np.where(in_hit, decay, 0.0), np.nan)
    # after the bounce: targets v=0, w=0 with the normal limits
    ov.b[sl] = np.where(mode == 1, 0.0, ov.b[sl])
    ov.d[sl] = np.where(mode == 1, 2.0, ov.d[sl])


_MOTION = {
    "acceleration": _acceleration,
    "twist": _twist,
    "oscillation": _oscillation,
    "stuck": _stuck,
    "spin": _spin,
    "back_and_forth": _back_and_forth,
    "collision": _collision,
}


@dataclass
class SensorExtras:
    """Extra per-sample increments added to the odometry estimate (output grid)."""

    left: np.ndarray  # wheel travel, metres
    right: np.ndarray
    x: np.ndarray  # pose increments the twist does not explain
    y: np.ndarray
    yaw: np.ndarray


def sensor_extras(events: list[Event], sample_s: np.ndarray) -> SensorExtras:
    """Wheel-slip and localization disturbances on the output sample times."""
    n = len(sample_s)
    ex = SensorExtras(*(np.zeros(n) for _ in range(5)))
    dts = np.diff(sample_s, prepend=sample_s[0] - (sample_s[1] - sample_s[0] if n > 1 else 0.01))
    for ev in events:
        if ev.kind not in SENSOR_KINDS:
            continue
        i0, i1 = np.searchsorted(sample_s, [ev.start_s, ev.end_s])
        if i1 <= i0:
            continue
        rng = np.random.default_rng(ev.seed)
        t = sample_s[i0:i1] - ev.start_s
        length = ev.end_s - ev.start_s
        dt = dts[i0:i1]
        sev = ev.severity
        if ev.kind == "wheel_slip":
            # one wheel spins up in one to three bursts while the robot barely moves with it
            bursts = int(rng.integers(1, 4))
            speed = np.zeros_like(t)
            for k in range(bursts):
                a = length * k / bursts
                w = length / bursts
                u = np.clip((t - a) / w, 0.0, 1.0)
                speed += rng.uniform(0.6, 1.0) * np.sin(np.pi * u) ** 2
            speed *= 0.25 + 0.6 * sev
            side = ex.left if rng.random() < 0.5 else ex.right
            side[i0:i1] += speed * dt * rng.choice([-1.0, 1.0], p=[0.2, 0.8])
        elif ev.kind == "pose_jump":
            jumps = int(rng.integers(1, 4))
            at = np.sort(rng.uniform(0.1, max(0.11, length - 0.1), jumps))
            for a in at:
                j = i0 + int(np.searchsorted(t, a))
                if j >= i1:
                    j = i1 - 1
                ang = rng.uniform(-np.pi, np.pi)
                dist = (0.15 + 0.6 * sev) * rng.uniform(0.7, 1.3)
                ex.x[j] += dist * math.cos(ang)
                ex.y[j] += dist * math.sin(ang)
                ex.yaw[j] += rng.choice([-1.0, 1.0]) * (0.05 + 0.35 * sev) * rng.uniform(0.5, 1.0)
        else:  # pose_twist_mismatch: the pose wanders while the twist says otherwise
            ramp = np.clip(np.minimum(t, length - t) / 0.2, 0.0, 1.0)
            vel = []
            for _ in range(3):
                f = rng.uniform(0.1, 0.6, 3)
                ph = rng.uniform(0, 2 * np.pi, 3)
                vel.append(np.sin(2 * np.pi * f[:, None] * t + ph[:, None]).sum(0) / 1.7)
            ex.x[i0:i1] += (0.1 + 0.35 * sev) * vel[0] * ramp * dt
            ex.y[i0:i1] += (0.1 + 0.35 * sev) * vel[1] * ramp * dt
            ex.yaw[i0:i1] += (0.1 + 0.5 * sev) * vel[2] * ramp * dt
    return ex
