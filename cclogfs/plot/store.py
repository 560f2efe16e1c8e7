"""PNG plots of any store: the trajectory, the speed and the stored windows over time, and
the anomaly scores of smart-logged windows and the summary stream's anomaly counts.

`plot_data` reads what is drawn (tests check these values); `plot_store` draws it.
Matplotlib's Agg backend (no display) comes from the demo's plots module.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InvalidInputError
from ..runs import hidden_by_default
from ..windowcount import count_records, link_of
from .figures import pyplot

POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
SUMMARY = "/cclog/summary"
NS = 1e9


@dataclass
class PlotData:
    """What the plots draw, times in ns."""

    topic: str
    stamp_ns: np.ndarray  # one per pose message
    x: np.ndarray
    y: np.ndarray
    speed: np.ndarray  # m/s: the twist when the message has one, else from consecutive poses
    window_of: np.ndarray  # index into `windows` of each pose message's window
    windows: dict[str, list[tuple[int, int]]] = field(default_factory=dict)  # stream -> (start, end)
    peaks: list[tuple[int, float]] = field(default_factory=list)  # (peak_ns, peak_score) per smart window
    summary: list[tuple[int, int, int]] = field(default_factory=list)  # (start_ns, end_ns, anomalies)
    undrawn: int = 0  # pose messages whose x, y or speed is not drawn (`_drawable`)
    # stream -> its windows as `cclog info` counts them (a smart window's parts once: `windowcount`)
    counted: dict[str, int] = field(default_factory=dict)

    @property
    def t0(self) -> int:
        starts = [a for spans in self.windows.values() for a, _ in spans]
        return min(starts) if starts else 0


def pose_topic(store: Any) -> str | None:
    """The stream to draw as the trajectory: the first of a pose type, else /odom, else None."""
    streams = sorted(store.streams())
    for name in streams:
        w = next(iter(store.query(name)), None)
        if w is not None and w.meta.get("msgtype") in POSE_TYPES:
            return name
    return "/odom" if "/odom" in streams else None


def _position(msg: dict, topic: str, stamp: int) -> tuple[float, float]:
    try:  # any JSON may be stored: a list, a number, a string for x
        pose = msg.get("pose", msg)
        pose = pose.get("pose", pose) if isinstance(pose, dict) else pose
        p = pose["position"]
        return float(p["x"]), float(p["y"])
    except (AttributeError, KeyError, TypeError, ValueError):
        raise InvalidInputError(f"{topic} at {stamp} ns: the message has no pose.position (or pose.pose.position); "
                                "name a pose stream with --topic") from None  # fmt: skip


def _twist_speed(msg: dict) -> float:
    try:
        lin = msg["twist"]["twist"]["linear"]
        return math.hypot(float(lin["x"]), float(lin["y"]))
    except (KeyError, TypeError):
        return math.nan


def plot_data(store: Any, topic: str | None = None) -> PlotData:
    """Read the pose stream `topic` (default `pose_topic`; none in a store without one),
    every stream's windows, the smart windows' peak scores and the summary stream's
    per-period anomaly counts."""
    if topic is not None and topic not in store.streams():
        raise InvalidInputError(f"the store has no stream {topic}")
    topic = topic or pose_topic(store)
    rows, window_of, windows, peaks, summary, records = [], [], {}, {}, [], []
    for w in store.query():
        if hidden_by_default(w.name):
            continue  # the runs' bookkeeping, stamped in wall time: not the robot's time line
        windows.setdefault(w.name, []).append((w.start_ns, w.end_ns))
        meta = w.meta
        records.append((w.seq, w.name, link_of(meta), w.continues))
        if w.name == SUMMARY:
            for _, text in w.messages():
                rec = json.loads(text)
                summary.append((rec["start_ns"], rec["end_ns"], int(rec.get("anomalies", 0))))
            continue
        if w.name == topic and meta.get("peak_score") is not None:  # a window's last part has its final peak
            peaks[meta.get("window_id", w.seq)] = (int(meta["peak_ns"]), float(meta["peak_score"]))
        if w.name == topic:
            for stamp, text in w.messages():
                msg = json.loads(text)
                rows.append((stamp, *_position(msg, topic, stamp), _twist_speed(msg)))
                window_of.append(len(windows[topic]) - 1)
    if not rows:
        empty = np.zeros(0)
        return PlotData(topic or "", empty.astype(np.int64), empty, empty, empty, empty.astype(int), windows,
                        sorted(peaks.values()), sorted(summary), counted=count_records(records).streams)  # fmt: skip
    order = np.argsort(np.array([r[0] for r in rows], dtype=np.int64), kind="stable")
    arr = np.array(rows, dtype=object)[order]
    stamp, x, y = arr[:, 0].astype(np.int64), arr[:, 1].astype(float), arr[:, 2].astype(float)
    speed = arr[:, 3].astype(float)
    bad = ~(_drawable(x) & _drawable(y))
    x[bad], y[bad] = math.nan, math.nan
    if np.isnan(speed).all() and len(x) > 1:  # no twist: from consecutive poses
        dt = np.diff(stamp) / NS
        with np.errstate(divide="ignore", invalid="ignore"):
            speed = np.concatenate([[math.nan], np.hypot(np.diff(x), np.diff(y)) / dt])
    bad |= ~_drawable(speed) & ~np.isnan(speed)
    speed[~_drawable(speed)] = math.nan
    return PlotData(topic, stamp, x, y, speed, np.array(window_of)[order], windows, sorted(peaks.values()),
                    sorted(summary), int(bad.sum()), counted=count_records(records).streams)  # fmt: skip


# Beyond this (metres, m/s) a value is junk, not a robot: matplotlib's axis limits and ticks
# overflow on values near 1e308 ("Axis limits cannot be NaN or Inf", a traceback).
_LARGEST = 1e100


def _drawable(values: np.ndarray) -> np.ndarray:
    """Which values can be drawn: finite and within _LARGEST."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(values) & (np.abs(values) <= _LARGEST)


def plot_store(data: PlotData, out: Path) -> list[Path]:
    """windows.png in `out` (created), and trajectory.png and speed.png when there are poses."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [_windows(data, out / "windows.png")]
    if len(data.x):
        paths += [_trajectory(data, out / "trajectory.png"), _speed(data, out / "speed.png")]
    return paths


def _breaks(data: PlotData, values: np.ndarray) -> np.ndarray:
    """`values` with NaN between windows, so no line joins two windows across a gap."""
    cut = np.flatnonzero(np.diff(data.window_of) != 0) + 1
    return np.insert(values.astype(float), cut, np.nan)


def _trajectory(data: PlotData, path: Path) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 7), dpi=110)
    ax.plot(_breaks(data, data.x), _breaks(data, data.y), color="tab:blue", lw=1.5, label=f"{data.topic} (stored)")
    ax.plot(data.x[0], data.y[0], "o", color="tab:green", label="first stored pose")
    ax.plot(data.x[-1], data.y[-1], "s", color="tab:red", label="last stored pose")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    n = data.counted.get(data.topic, 0)
    ax.set_title(f"Trajectory: {len(data.x):,} stored poses in {n:,} windows")
    ax.legend(loc="best", fontsize=8)
    return _save(plt, fig, path)


def _speed(data: PlotData, path: Path) -> Path:
    """Speed with the stored windows shaded; below it, when the store has them, each smart
    window's peak anomaly score and the summary's anomalous messages per period."""
    plt = pyplot()
    t0 = data.t0
    scored = bool(data.peaks or data.summary)
    fig, axes = plt.subplots(2 if scored else 1, 1, figsize=(11, 6.4 if scored else 4.4), dpi=110, sharex=True,
                             squeeze=False)  # fmt: skip
    ax = axes[0][0]
    for k, (a, b) in enumerate(data.windows.get(data.topic, [])):
        ax.axvspan((a - t0) / NS, (b - t0) / NS, color="tab:blue", alpha=0.12, label="stored window" if k == 0 else None)
    sec = (data.stamp_ns - t0) / NS
    ax.plot(_breaks(data, sec), _breaks(data, data.speed), color="k", lw=0.8, label="speed")
    ax.set_ylabel("speed (m/s)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"Speed of {data.topic} and the stored windows")
    if scored:
        low = axes[1][0]
        if data.summary:
            low.bar([(a - t0) / NS for a, _, _ in data.summary], [n for *_, n in data.summary], align="edge",
                    width=[(b - a) / NS for a, b, _ in data.summary], color="tab:orange", alpha=0.35,
                    edgecolor="tab:orange", label="anomalous messages per summary period")  # fmt: skip
            low.set_ylabel("anomalous messages")
            low.legend(loc="upper left", fontsize=8)
        if data.peaks:
            top = low.twinx() if data.summary else low
            top.plot([(t - t0) / NS for t, _ in data.peaks], [v for _, v in data.peaks], "v", color="tab:red",
                     label="peak anomaly score of a window")  # fmt: skip
            top.set_ylabel("score (> 0: anomalous)")
            top.legend(loc="upper right", fontsize=8)
        low.set_xlabel("time (s)")
    else:
        ax.set_xlabel("time (s)")
    return _save(plt, fig, path)


def _windows(data: PlotData, path: Path) -> Path:
    plt = pyplot()
    t0 = data.t0
    names = sorted(data.windows)
    fig, ax = plt.subplots(figsize=(11, 1.2 + 0.5 * len(names)), dpi=110)
    for row, name in enumerate(names):
        spans = [((a - t0) / NS, max((b - a) / NS, 1e-3)) for a, b in data.windows[name]]
        ax.broken_barh(spans, (row - 0.35, 0.7), color="tab:blue" if name != SUMMARY else "tab:orange")
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel("time (s)")
    ax.set_title("Stored windows per stream")
    return _save(plt, fig, path)


def _save(plt: Any, fig: Any, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
