"""The closed loop: goals, A* routes, pure pursuit, dynamic limits, motor lag.

The loop runs at a fixed internal step (100 Hz, or the output rate when that is higher);
the controller updates at 20 Hz like a navigation stack's. It is plain scalar Python on
purpose: about a microsecond per operation beats numpy's per-call overhead on scalars,
and a closed loop cannot be vectorized over time. Anomaly overrides are precomputed
arrays, so the loop only reads them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .anomalies import Overrides
from .world import Building

__all__ = ["RobotParams", "Truth", "drive"]

CONTROL_HZ = 20.0


@dataclass(frozen=True)
class RobotParams:
    """A BWIBot-like differential drive (Segway RMP 110 base) with indoor limits."""

    v_max: float = 1.0  # m/s, indoor cap
    w_max: float = 1.2  # rad/s
    a_max: float = 0.8  # m/s^2 (drawn per run between 0.55 and 1.0)
    jerk_max: float = 3.0  # m/s^3
    alpha_max: float = 2.5  # rad/s^2
    alpha_jerk: float = 12.0  # rad/s^3
    tau_v: float = 0.12  # s, first-order motor lag
    tau_w: float = 0.10
    a_lat: float = 0.5  # m/s^2, lateral comfort limit in turns
    wheel_base: float = 0.53  # m


@dataclass
class Truth:
    """What the robot really did, on the internal grid."""

    dt: float
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray  # unwrapped
    v: np.ndarray
    w: np.ndarray
    goals: int  # goals reached


def _people(rng: np.random.Generator, n_ctrl: int, ctrl_dt: float) -> list[float]:
    """Speed factor per control step: pauses and slow-downs around people."""
    factor = np.ones(n_ctrl)
    t = rng.exponential(40.0)
    total = n_ctrl * ctrl_dt
    while t < total:
        if rng.random() < 0.4:
            length, f = rng.uniform(1.0, 5.0), 0.0
        else:
            length, f = rng.uniform(2.0, 9.0), rng.uniform(0.25, 0.6)
        i0, i1 = int(t / ctrl_dt), int((t + length) / ctrl_dt)
        factor[i0:i1] = np.minimum(factor[i0:i1], f)
        t += length + rng.exponential(40.0)
    return factor.tolist()


class _Pursuit:
    """Pure pursuit along a polyline, with rotate-in-place for large heading errors."""

    def __init__(self, rng: np.random.Generator, p: RobotParams, dt: float):
        self.rng = rng
        self.dt = dt
        self.best, self.stalled = math.inf, 0
        self.p = p
        self.w_rot = float(rng.uniform(0.5, 0.9))
        self.look_gain = float(rng.uniform(0.6, 1.1))
        self.path: list[tuple[float, float]] = []
        self.seg = 0
        self.cruise = 0.6

    def set_path(self, pts: list[tuple[float, float]]) -> None:
        # drop repeated points, which would make zero-length segments
        clean = [pts[0]]
        for q in pts[1:]:
            if math.hypot(q[0] - clean[-1][0], q[1] - clean[-1][1]) > 0.05:
                clean.append(q)
        if len(clean) == 1:
            clean.append(clean[0])
        self.path = clean
        self.seg = 0
        self.best, self.stalled = math.inf, 0
        # each leg has its own cruise speed: some trips hurried, some leisurely
        self.cruise = float(self.rng.uniform(0.4, self.p.v_max))

    def command(self, x: float, y: float, th: float, v: float) -> tuple[float, float, bool]:
        """(v, w) command and whether the goal is reached."""
        path = self.path
        gx, gy = path[-1]
        dgoal = math.hypot(gx - x, gy - y)
        if dgoal < 0.25:
            return 0.0, 0.0, True  # nav2's default xy goal tolerance
        # no progress for a while (circling a goal it cannot reach): give the goal up
        if dgoal < self.best - 0.3:
            self.best, self.stalled = dgoal, 0
        else:
            self.stalled += 1
            if self.stalled * self.dt > 20.0:
                return 0.0, 0.0, True
        # advance along segments while the robot is past the current one's end
        while self.seg < len(path) - 2:
            ax, ay = path[self.seg]
            bx, by = path[self.seg + 1]
            sx, sy = bx - ax, by - ay
            u = ((x - ax) * sx + (y - ay) * sy) / (sx * sx + sy * sy)
            if u < 1.0:
                break
            self.seg += 1
        ax, ay = path[self.seg]
        bx, by = path[self.seg + 1]
        sx, sy = bx - ax, by - ay
        seglen = math.hypot(sx, sy) or 1e-9
        u = max(0.0, min(1.0, ((x - ax) * sx + (y - ay) * sy) / (seglen * seglen)))
        look = max(0.5, min(1.6, 0.5 + self.look_gain * abs(v)))
        # walk `look` metres along the path from the projection
        px, py = ax + u * sx, ay + u * sy
        remain = look
        i = self.seg
        cx, cy = px, py
        while True:
            nx, ny = path[i + 1]
            d = math.hypot(nx - cx, ny - cy)
            if d >= remain or i + 2 >= len(path):
                r = min(1.0, remain / d) if d > 1e-9 else 0.0
                lx, ly = cx + r * (nx - cx), cy + r * (ny - cy)
                break
            remain -= d
            cx, cy = nx, ny
            i += 1
        dx, dy = lx - x, ly - y
        c, s = math.cos(th), math.sin(th)
        fx, fy = c * dx + s * dy, -s * dx + c * dy
        alpha = math.atan2(fy, fx)
        if abs(alpha) > 0.9:
            return 0.0, math.copysign(self.w_rot, alpha), False  # rotate in place first
        d2 = fx * fx + fy * fy
        kappa = 2.0 * fy / d2 if d2 > 1e-9 else 0.0
        vcmd = self.cruise
        if abs(kappa) > 1e-6:
            vcmd = min(vcmd, math.sqrt(self.p.a_lat / abs(kappa)))
        vcmd = min(vcmd, math.sqrt(2.0 * 0.5 * dgoal) + 0.05)
        vcmd *= max(0.3, math.cos(alpha))
        wcmd = max(-self.p.w_max, min(self.p.w_max, vcmd * kappa))
        return vcmd, wcmd, False


def drive(
    rng: np.random.Generator,
    building: Building,
    params: RobotParams,
    n: int,
    dt: float,
    ov: Overrides,
) -> Truth:
    """Run the loop for n internal steps of dt seconds.

    One long function on purpose: the step loop runs 360,000 times for an hour at 100 Hz,
    with its state in locals; splitting it into calls per step (controller, limits,
    integration) would add their call overhead to every step (`python3 dev.py bench sim_speed`
    times it).
    """
    p = params
    a_max = p.a_max
    ctrl_every = max(1, round(1.0 / (CONTROL_HZ * dt)))
    people = _people(rng, n // ctrl_every + 1, ctrl_every * dt)
    pursuit = _Pursuit(rng, p, ctrl_every * dt)

    start = int(rng.choice(building.rooms))
    x, y = map(float, building.xy[start] + rng.uniform(-1.0, 1.0, 2))
    th = float(rng.uniform(-math.pi, math.pi))
    goal_node, gx, gy = building.random_goal(rng)

    def plan(x: float, y: float) -> None:
        nodes = building.astar(building.nearest(x, y), goal_node)
        # the goal replaces its own node, so the last leg never doubles back
        pts = [(x, y)] + [tuple(building.xy[k]) for k in nodes[:-1]] + [(gx, gy)]
        # skip the first node when it lies behind the robot on the way to the second
        if len(pts) > 3:
            (ax, ay), (bx, by) = pts[1], pts[2]
            if (ax - x) * (bx - ax) + (ay - y) * (by - ay) < 0:
                pts.pop(1)
        pursuit.set_path(pts)

    plan(x, y)
    dwell_until = float(rng.uniform(1.0, 3.0))
    goals = 0

    mode_l = ov.mode.tolist()
    oa, ob, oc, od = ov.a.tolist(), ov.b.tolist(), ov.c.tolist(), ov.d.tolist()
    xs, ys, ths, vs, ws = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n

    v = w = 0.0  # actual speeds
    sv = av = sw = aw = 0.0  # setpoints after accel/jerk limits, and their rates
    vcmd = wcmd = 0.0
    kv, kw = dt / p.tau_v, dt / p.tau_w
    jerk, ajerk = p.jerk_max * dt, p.alpha_jerk * dt
    was_overridden = False
    for i in range(n):
        t = i * dt
        mode = mode_l[i]
        if i % ctrl_every == 0:
            if mode == 0 and was_overridden:
                plan(x, y)  # an anomaly knocked the robot off its route
            was_overridden = mode != 0
            if t < dwell_until:
                vcmd = wcmd = 0.0
            else:
                vcmd, wcmd, done = pursuit.command(x, y, th, v)
                if done:
                    goals += 1
                    # dwell: mostly short stops, sometimes a long wait (a delivery)
                    dwell = rng.uniform(1.0, 6.0) if rng.random() < 0.8 else rng.uniform(8.0, 20.0)
                    dwell_until = t + dwell
                    goal_node, gx, gy = building.random_goal(rng)
                    plan(x, y)
                else:
                    f = people[i // ctrl_every]
                    vcmd *= f
                    wcmd *= f if f > 0.0 else 0.0
        if mode == 2:
            v = oa[i] + ob[i] * v
            w = oc[i] + od[i] * w
            sv, av, sw, aw = v, 0.0, w, 0.0
        else:
            if mode == 1:
                vr = vcmd if oa[i] != oa[i] else oa[i]
                wr = wcmd if ob[i] != ob[i] else ob[i]
                al = a_max if oc[i] != oc[i] else oc[i]
                wl = p.alpha_max if od[i] != od[i] else od[i]
            else:
                vr, wr, al, wl = vcmd, wcmd, a_max, p.alpha_max
            # acceleration-limited tracking, with the acceleration itself jerk-limited
            ad = (vr - sv) * 3.0
            ad = al if ad > al else (-al if ad < -al else ad)
            j = jerk * al / a_max
            da = ad - av
            av += j if da > j else (-j if da < -j else da)
            sv += av * dt
            ad = (wr - sw) * 5.0
            ad = wl if ad > wl else (-wl if ad < -wl else ad)
            j = ajerk * wl / p.alpha_max
            da = ad - aw
            aw += j if da > j else (-j if da < -j else da)
            sw += aw * dt
            v += (sv - v) * kv
            w += (sw - w) * kw
        h = th + 0.5 * w * dt
        x += v * math.cos(h) * dt
        y += v * math.sin(h) * dt
        th += w * dt
        xs[i], ys[i], ths[i], vs[i], ws[i] = x, y, th, v, w
    return Truth(dt, np.array(xs), np.array(ys), np.array(ths), np.array(vs), np.array(ws), goals)
