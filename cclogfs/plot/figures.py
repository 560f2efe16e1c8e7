"""PNG plots of a run: the trajectory with stored windows, and the anomaly score over time."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def pyplot():
    import matplotlib

    matplotlib.use("Agg")  # files only: no display needed
    import matplotlib.pyplot as plt

    return plt


def _inside(stamps: np.ndarray, spans: list[tuple[int, int]]) -> np.ndarray:
    mask = np.zeros(len(stamps), dtype=bool)
    for a, b in spans:
        mask[np.searchsorted(stamps, a) : np.searchsorted(stamps, b, side="right")] = True
    return mask


def plot_trajectory(path: Path, run: Any, windows: list[tuple[int, int]]) -> Path:
    """The path driven (odometry), stored windows highlighted, true anomalies marked."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 7), dpi=110)
    ax.plot(run.x, run.y, color="0.75", lw=1, label="trajectory (odometry)")
    kept = _inside(run.stamp_ns, windows)
    xs, ys = np.where(kept, run.x, np.nan), np.where(kept, run.y, np.nan)
    ax.plot(xs, ys, color="tab:blue", lw=3, alpha=0.8, label="stored logging windows")
    for k, ev in enumerate(run.events):
        i = min(int(np.searchsorted(run.stamp_ns, ev.start_ns)), len(run.x) - 1)
        ax.plot(run.x[i], run.y[i], "x", color="tab:red", ms=11, mew=2.5,
                label="true anomaly (start)" if k == 0 else None)  # fmt: skip
        ax.annotate(ev.kind, (run.x[i], run.y[i]), textcoords="offset points", xytext=(6, 6),
                    color="tab:red", fontsize=8)  # fmt: skip
    ax.plot(run.x[0], run.y[0], "o", color="tab:green", label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("Simulated run: what smart logging kept")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_scores(path: Path, stamps: np.ndarray, scores: np.ndarray, windows: list[tuple[int, int]],
                events: list[dict]) -> Path:  # fmt: skip
    """Anomaly score over time, the threshold, stored windows and the true anomalies."""
    plt = pyplot()
    t0 = stamps[0]
    sec = (stamps - t0) / 1e9
    fig, ax = plt.subplots(figsize=(11, 4.4), dpi=110)
    for k, (a, b) in enumerate(windows):
        ax.axvspan((a - t0) / 1e9, (b - t0) / 1e9, color="tab:blue", alpha=0.18,
                   label="stored window" if k == 0 else None)  # fmt: skip
    for k, e in enumerate(events):
        ax.axvspan((e["start_ns"] - t0) / 1e9, (e["end_ns"] - t0) / 1e9, ymin=0.93, ymax=1.0,
                   color="tab:red", label="true anomaly" if k == 0 else None)  # fmt: skip
    ax.plot(sec, scores, color="k", lw=0.7, label="anomaly score")
    ax.axhline(0.0, color="tab:orange", ls="--", lw=1.2, label="threshold")
    finite = scores[np.isfinite(scores)]
    if len(finite):
        lo, hi = np.percentile(finite, 0.5), max(float(finite.max()), 0.5)
        ax.set_ylim(lo - 0.1 * (hi - lo), hi + 0.15 * (hi - lo))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("score (> 0: anomalous)")
    ax.set_title("Anomaly score of each odometry message")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=8, ncol=4, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
