"""What the robot reports: wheel-encoder odometry and an IMU, on jittered sample times.

Odometry is computed the way a base driver does it: each wheel's travel between two
encoder reads (true travel, times a per-run scale error, plus noise and tick
quantization), divided by the time between the reads for the twist, and integrated
for the pose with a slightly wrong wheel base, so the pose drifts like real odometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .anomalies import SensorExtras
from .drive import Truth

__all__ = ["Calibration", "Reported", "sample_times", "odometry", "imu"]

TICK_M = 1e-5  # encoder resolution in wheel travel (high-count encoders on the RMP base)
GRAVITY = 9.80665


def sample_times(rng: np.random.Generator, n: int, rate_hz: float) -> np.ndarray:
    """Encoder read times (s): the nominal grid plus scheduling jitter, strictly increasing."""
    period = 1.0 / rate_hz
    jitter = np.clip(rng.normal(0.0, 0.03 * period, n), -0.2 * period, 0.2 * period)
    # now and then the driver thread runs late
    late = rng.random(n) < 0.003
    jitter[late] = rng.uniform(0.2, 0.45, int(late.sum())) * period
    t = np.arange(n) * period + jitter
    t[0] = 0.0
    return t


@dataclass
class Reported:
    """Odometry as published: pose in the odom frame and body twist."""

    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray  # wrapped to [-pi, pi)
    vx: np.ndarray
    wz: np.ndarray


@dataclass(frozen=True)
class Calibration:
    """A robot's odometry errors: wheel travel scale per side, wheel-base estimate factor."""

    scale_l: float
    scale_r: float
    base: float


def _wheel_travel(truth: Truth, b: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cumulative left/right wheel travel on the internal grid, and its time axis."""
    dt = truth.dt
    t = np.arange(len(truth.v) + 1) * dt
    left = np.concatenate(([0.0], np.cumsum((truth.v - 0.5 * b * truth.w) * dt)))
    right = np.concatenate(([0.0], np.cumsum((truth.v + 0.5 * b * truth.w) * dt)))
    return t, left, right


def odometry(
    rng: np.random.Generator,
    truth: Truth,
    t: np.ndarray,
    wheel_base: float,
    x0: float,
    y0: float,
    yaw0: float,
    extras: SensorExtras,
    *,
    calibration: Calibration | None = None,
    heading: np.ndarray | None = None,
) -> Reported:
    """Wheel odometry sampled at read times t (s).

    `calibration` replaces the per-run draws of the robot's errors (the draws are still
    made, so the noise stays the same). `heading` (unwrapped IMU yaw at t) replaces the
    wheels' yaw in the pose; the twist stays the wheels'."""
    tt, left, right = _wheel_travel(truth, wheel_base)
    period = (t[-1] - t[0]) / max(1, len(t) - 1) if len(t) > 1 else 0.01
    reads = np.concatenate(([t[0] - period], t))
    # the truth grid starts at rest, so reads before it see no motion
    scale_l, scale_r = 1.0 + rng.normal(0.0, 0.002, 2)
    if calibration is not None:
        scale_l, scale_r = calibration.scale_l, calibration.scale_r
    cum_l = scale_l * np.interp(reads, tt, left)
    cum_r = scale_r * np.interp(reads, tt, right)
    # noise in proportion to travel (tyre and floor), so a robot at rest reads exactly zero;
    # white noise is kept small because differencing 100 Hz odometry amplifies it
    noise_l = 0.003 * np.abs(np.diff(cum_l)) * rng.normal(0.0, 1.0, len(t))
    noise_r = 0.003 * np.abs(np.diff(cum_r)) * rng.normal(0.0, 1.0, len(t))
    cum_l[1:] += np.cumsum(noise_l + extras.left)
    cum_r[1:] += np.cumsum(noise_r + extras.right)
    dl = np.diff(np.round(cum_l / TICK_M)) * TICK_M
    dr = np.diff(np.round(cum_r / TICK_M)) * TICK_M
    b_est = wheel_base * (1.0 + rng.normal(0.0, 0.003))
    if calibration is not None:
        b_est = wheel_base * calibration.base
    dtr = np.diff(reads)
    ds, dth = 0.5 * (dl + dr), (dr - dl) / b_est
    vx, wz = ds / dtr, dth / dtr
    if heading is not None:  # the pose turns with the gyro, the twist with the wheels
        dth_pose = np.diff(heading, prepend=heading[0])
    else:
        dth_pose = dth
    yaw = yaw0 + np.cumsum(dth_pose + extras.yaw)
    mid = yaw - 0.5 * (dth_pose + extras.yaw)
    x = x0 + np.cumsum(ds * np.cos(mid) + extras.x)
    y = y0 + np.cumsum(ds * np.sin(mid) + extras.y)
    yaw = (yaw + np.pi) % (2.0 * np.pi) - np.pi
    return Reported(x, y, yaw, vx, wz)


@dataclass
class ImuData:
    """IMU readings: yaw estimate, gyro z, accelerometer x/y/z."""

    yaw: np.ndarray
    gz: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    az: np.ndarray


def imu(rng: np.random.Generator, truth: Truth, t: np.ndarray) -> ImuData:
    """Gyro and accelerometer at read times t (s): truth plus bias and noise."""
    tt = np.arange(len(truth.v)) * truth.dt
    v = np.interp(t, tt, truth.v)
    w = np.interp(t, tt, truth.w)
    acc = np.interp(t, tt, np.gradient(truth.v, truth.dt))
    yaw_true = np.interp(t, tt, truth.yaw)
    n = len(t)
    bias = rng.normal(0.0, 0.003)
    gz = w + bias + rng.normal(0.0, 0.01, n)
    # the IMU's own heading integrates the gyro bias
    yaw = yaw_true + bias * (t - t[0])
    yaw = (yaw + np.pi) % (2.0 * np.pi) - np.pi
    ax = acc + rng.normal(0.0, 0.05, n)
    ay = v * w + rng.normal(0.0, 0.05, n)
    az = GRAVITY + rng.normal(0.0, 0.05, n)
    return ImuData(yaw, gz, ax, ay, az)
