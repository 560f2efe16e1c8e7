"""Test and benchmark helpers: read odometry from a bag, resample it, inject anomalies.

The injector edits an `OdomArrays` in place of a simulator: each anomaly changes the twist
and integrates the pose consistently (except a pose jump, which breaks that on purpose),
and is returned as a labelled event `{"start_ns", "end_ns", "kind"}`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .features import NS, OdomArrays

__all__ = ["KINDS", "inject", "odom_texts", "read_odometry", "resample"]

KINDS = ("accel", "pose_jump", "spin", "stop", "twist", "oscillate", "slip")


def read_odometry(path: str | Path, topic: str = "/odom") -> list[str]:
    """Rosbridge JSON texts of one topic of a bag or MCAP file, in log order."""
    from rosbags.highlevel import AnyReader

    from ..jsontext.ros import message_to_json

    with AnyReader([Path(path)]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [
            message_to_json(reader.deserialize(raw, con.msgtype))
            for con, _, raw in reader.messages(connections=conns)
        ]


def odom_texts(odom: OdomArrays) -> list[str]:
    """OdomArrays back to rosbridge-style nav_msgs/Odometry JSON texts."""
    out = []
    for stamp, r in zip(odom.stamp_ns.tolist(), odom.raw.tolist()):
        xyz = lambda a: {"x": a[0], "y": a[1], "z": a[2]}  # noqa: E731
        out.append(json.dumps({
            "header": {"stamp": {"sec": stamp // NS, "nanosec": stamp % NS}, "frame_id": "odom"},
            "child_frame_id": "base_link",
            "pose": {"pose": {"position": xyz(r[0:3]),
                              "orientation": {"x": r[3], "y": r[4], "z": r[5], "w": r[6]}},
                     "covariance": [0.0] * 36},
            "twist": {"twist": {"linear": xyz(r[7:10]), "angular": xyz(r[10:13])},
                      "covariance": [0.0] * 36},
        }))  # fmt: skip
    return out


def _yaw(raw: np.ndarray) -> np.ndarray:
    qx, qy, qz, qw = raw[:, 3], raw[:, 4], raw[:, 5], raw[:, 6]
    return np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))


def _set_yaw(raw: np.ndarray, yaw: np.ndarray) -> None:
    raw[:, 3:7] = np.column_stack([0 * yaw, 0 * yaw, np.sin(yaw / 2), np.cos(yaw / 2)])


def resample(odom: OdomArrays, rate_hz: float, *, jitter_s: float = 0.0, seed: int = 0,
             integrate: bool = False) -> OdomArrays:  # fmt: skip
    """The run at another rate (linear interpolation, gaps over 1 s kept), stamps jittered.

    `integrate`: the pose integrated from the resampled twist (trapezoid, mid-step heading;
    from the interpolated pose after each gap), as a robot publishing at that rate would
    report it. Interpolated on its own, the pose follows the source's integration steps
    while the twist ramps between its samples: at 100 Hz from 10 Hz that disagreement
    reached 0.2 m/s, a mismatch no robot at 100 Hz would show."""
    t = odom.stamp_ns
    step = int(NS / rate_hz)
    new_t = np.arange(t[0], t[-1], step, dtype=np.int64)
    # Keep real gaps: drop new samples that fall inside a gap of the source.
    gap = np.nonzero(np.diff(t) > NS)[0]
    for g in gap:
        new_t = new_t[(new_t <= t[g]) | (new_t >= t[g + 1])]
    tf = (t - t[0]) * 1e-9
    nf = (new_t - t[0]) * 1e-9
    raw = np.column_stack([np.interp(nf, tf, odom.raw[:, c]) for c in range(odom.raw.shape[1])])
    yaw = np.interp(nf, tf, np.unwrap(_yaw(odom.raw)))
    if integrate and len(new_t) > 1:
        yaw = _integrate_pose(raw, new_t, yaw)
    _set_yaw(raw, yaw)
    if jitter_s:
        rng = np.random.default_rng(seed)
        new_t = new_t + (rng.uniform(-jitter_s, jitter_s, len(new_t)) * NS).astype(np.int64)
    return OdomArrays(new_t, raw)


def _integrate_pose(raw: np.ndarray, t: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Overwrite x, y of `raw` with the twist integrated over stamps t (trapezoid, mid-step
    heading), restarting from the given pose after each gap over 1 s; the new yaw."""
    starts = np.concatenate([[0], np.nonzero(np.diff(t) > NS)[0] + 1, [len(t)]])
    out = yaw.copy()
    for a, b in zip(starts[:-1], starts[1:]):
        dt = np.diff(t[a:b]) * 1e-9
        w = 0.5 * (raw[a + 1 : b, 12] + raw[a : b - 1, 12])
        out[a:b] = yaw[a] + np.concatenate([[0.0], np.cumsum(w * dt)])
        mid = out[a : b - 1] + 0.5 * w * dt
        vx = 0.5 * (raw[a + 1 : b, 7] + raw[a : b - 1, 7])
        vy = 0.5 * (raw[a + 1 : b, 8] + raw[a : b - 1, 8])
        for col, step in ((0, np.cos(mid) * vx - np.sin(mid) * vy), (1, np.sin(mid) * vx + np.cos(mid) * vy)):
            raw[a:b, col] = raw[a, col] + np.concatenate([[0.0], np.cumsum(step * dt)])
    return out


def _integrate(raw: np.ndarray, t: np.ndarray, a: int, b: int) -> None:
    """Recompute pose from twist on rows a..b-1 (starting from row a-1), shift the rest."""
    yaw = _yaw(raw)
    old_end_pos, old_end_yaw = raw[b - 1, 0:2].copy(), yaw[b - 1]
    for i in range(a, b):
        dt = (t[i] - t[i - 1]) * 1e-9
        w = 0.5 * (raw[i, 12] + raw[i - 1, 12])
        mid = yaw[i - 1] + 0.5 * w * dt
        v = 0.5 * (raw[i, 7] + raw[i - 1, 7])
        raw[i, 0] = raw[i - 1, 0] + np.cos(mid) * v * dt
        raw[i, 1] = raw[i - 1, 1] + np.sin(mid) * v * dt
        yaw[i] = yaw[i - 1] + w * dt
    # The rest of the run continues from where the anomaly left the robot (rigid motion).
    d_yaw = yaw[b - 1] - old_end_yaw
    c, s = np.cos(d_yaw), np.sin(d_yaw)
    rel = raw[b:, 0:2] - old_end_pos
    raw[b:, 0] = raw[b - 1, 0] + c * rel[:, 0] - s * rel[:, 1]
    raw[b:, 1] = raw[b - 1, 1] + s * rel[:, 0] + c * rel[:, 1]
    yaw[b:] += d_yaw
    _set_yaw(raw[a:], yaw[a:])


def inject(odom: OdomArrays, kind: str, start_ns: int, duration_s: float, *, strength: float = 1.0):
    """A copy of the run with one anomaly from start_ns, and its label event."""
    t, raw = odom.stamp_ns, odom.raw.copy()
    a = int(np.searchsorted(t, start_ns))
    b = int(np.searchsorted(t, start_ns + int(duration_s * NS)))
    b = max(b, a + 1)
    tau = (t[a:b] - t[a]) * 1e-9
    if kind == "accel":  # lurch forward: +0.6 m/s in 0.1 s, then back
        bump = 0.6 * strength * np.clip(np.minimum(tau, duration_s - tau) / 0.1, 0, 1)
        raw[a:b, 7] += bump
    elif kind == "twist":  # sudden yaw-rate spike
        raw[a:b, 12] += 1.5 * strength * np.clip(np.minimum(tau, duration_s - tau) / 0.1, 0, 1)
    elif kind == "spin":  # spin in place
        raw[a:b, 7] = 0.0
        raw[a:b, 12] = 1.2 * strength
    elif kind == "stop":  # collision: speed to zero within one message, then stay stopped
        raw[a:b, 7] = 0.0
        raw[a:b, 12] = 0.0
    elif kind == "oscillate":  # planner dithering: back and forth at 1 Hz
        raw[a:b, 7] = 0.2 * strength * np.sign(np.sin(2 * np.pi * tau))
        raw[a:b, 12] = 0.5 * strength * np.sign(np.sin(2 * np.pi * tau + 1))
    elif kind == "slip":  # wheel slip: the wheels report extra speed the pose does not show
        raw[a:b, 7] += 0.4 * strength * np.clip(np.minimum(tau, duration_s - tau) / 0.1, 0, 1)
        return OdomArrays(t.copy(), raw), {"start_ns": int(t[a]), "end_ns": int(t[b - 1]), "kind": kind}
    elif kind == "pose_jump":  # localization jump: pose moves 0.5 m sideways, twist does not
        yaw = _yaw(raw[a : a + 1])[0]
        raw[a:, 0] += -np.sin(yaw) * 0.5 * strength
        raw[a:, 1] += np.cos(yaw) * 0.5 * strength
        return OdomArrays(t.copy(), raw), {"start_ns": int(t[a]), "end_ns": int(t[min(a + 1, len(t) - 1)]), "kind": kind}
    else:
        raise ValueError(f"unknown anomaly kind {kind!r}")
    _integrate(raw, t, a, b)
    return OdomArrays(t.copy(), raw), {"start_ns": int(t[a]), "end_ns": int(t[b - 1]), "kind": kind}
