"""Odometry parsing and feature extraction (batch and live give the same vectors).

Two feature sets share one interface (`get_config`, `batch`, `stream`):

- `paper`: the CC-Log paper's raw concatenation of pose position, orientation, linear and
  angular twist over the last `window` messages (every `stride`-th one); 500/2 gives the
  paper's 3,250 features.
- `default`: per-second motion quantities that do not depend on where the robot is, which
  way it faces or how fast odometry is published (see `DefaultFeatures`).
"""

from __future__ import annotations

import json
import re
from collections import deque
from math import atan2, cos, hypot, inf, isfinite, pi, sin
from dataclasses import dataclass
from typing import Any, Iterable, Protocol

import numpy as np

from ..errors import InvalidInputError

__all__ = [
    "DefaultFeatures",
    "FeatureSet",
    "OdomArrays",
    "PaperFeatures",
    "make_features",
    "TwistFromPoses",
    "odom_row",
    "parse_odometry",
]

NS = 1_000_000_000
# Per message: position xyz, orientation xyzw, linear twist xyz, angular twist xyz.
RAW_WIDTH = 13
# Column names of OdomArrays.raw, to name a bad or non-finite value.
RAW_NAMES = tuple(
    [f"pose.position.{k}" for k in "xyz"] + [f"pose.orientation.{k}" for k in "xyzw"]
    + [f"twist.linear.{k}" for k in "xyz"] + [f"twist.angular.{k}" for k in "xyz"]
)  # fmt: skip
TWO_PI = 2 * pi


@dataclass
class OdomArrays:
    """A run of odometry messages as arrays: stamps (int64 ns) and a (n, 13) float64 block."""

    stamp_ns: np.ndarray
    raw: np.ndarray

    def __len__(self) -> int:
        return len(self.stamp_ns)

    @property
    def position(self) -> np.ndarray:
        return self.raw[:, 0:3]

    @property
    def orientation(self) -> np.ndarray:
        return self.raw[:, 3:7]

    @property
    def linear(self) -> np.ndarray:
        return self.raw[:, 7:10]

    @property
    def angular(self) -> np.ndarray:
        return self.raw[:, 10:13]

    def take(self, index: Any) -> OdomArrays:
        """Rows selected by a slice, mask or index array."""
        return OdomArrays(self.stamp_ns[index], self.raw[index])

    @classmethod
    def concat(cls, parts: Iterable[OdomArrays]) -> OdomArrays:
        parts = list(parts)
        if not parts:
            return cls(np.empty(0, np.int64), np.empty((0, RAW_WIDTH)))
        return cls(
            np.concatenate([p.stamp_ns for p in parts]), np.concatenate([p.raw for p in parts])
        )


# Possessive quantifiers and the unrolled string loop match the same texts as the plain
# JSON grammar (a delimiter always follows) without backtracking: ~25 % faster per message.
_NUM = r"(-?(?:0|[1-9][0-9]*+)(?:\.[0-9]++)?+(?:[eE][-+]?[0-9]++)?+|NaN|-?Infinity)"
_STR = r'"[^"\\]*+(?:\\.[^"\\]*+)*+"'
_XYZ = '\\{"x": ' + _NUM + ', "y": ' + _NUM + ', "z": ' + _NUM + "\\}"
_COV = r"\[[^]]*\]"  # not checked: sources have validated the JSON already
# The whole message in the layout json.dumps gives rosbridge JSON (fields in definition
# order; ROS 1 headers have a seq): a full match needs no json.loads, which would spend
# most of its time on the two 36-value covariance arrays we do not use.
_ODOM_TEXT = re.compile(
    '\\{"header": \\{(?:"seq": [0-9]+, )?"stamp": \\{"(?:sec|secs)": ([0-9]+), "(?:nanosec|nsecs)": ([0-9]+)\\}, '
    f'"frame_id": {_STR}\\}}, "child_frame_id": {_STR}, "pose": \\{{"pose": \\{{"position": {_XYZ}, '
    f'"orientation": \\{{"x": {_NUM}, "y": {_NUM}, "z": {_NUM}, "w": {_NUM}\\}}\\}}, '
    f'"covariance": {_COV}\\}}, "twist": \\{{"twist": \\{{"linear": {_XYZ}, "angular": {_XYZ}\\}}, '
    f'"covariance": {_COV}\\}}\\}}'
)


def _pose_fields(msg: dict) -> tuple[dict, dict, dict, dict | None]:
    """(stamp, position, orientation, twist or None) of an Odometry, PoseWithCovarianceStamped,
    PoseStamped, TransformStamped, or a TFMessage holding one transform. `_pose_fields_checked`
    walks the same fields naming the one that is not an object."""
    if "transforms" in msg and "header" not in msg:
        if len(msg["transforms"]) != 1:
            raise KeyError(f"transforms holds {len(msg['transforms'])} frames, not 1")
        msg = msg["transforms"][0]
    stamp = msg["header"]["stamp"]
    if "transform" in msg:
        t = msg["transform"]
        return stamp, t["translation"], t["rotation"], None
    pose = msg["pose"]
    pose = pose["pose"] if "pose" in pose else pose
    twist = msg["twist"]["twist"] if "twist" in msg else None
    return stamp, pose["position"], pose["orientation"], twist


def _pose_fields_checked(msg: Any) -> None:
    """`_pose_fields`' walk, a ValueError naming the path of the first field that is not an
    object (null...): run once `_pose_fields` failed, so good messages pay nothing for it.
    Python's own words ("argument of type 'NoneType' is not iterable") named no field."""
    msg = _obj(msg, "the message")
    if "transforms" in msg and "header" not in msg:
        if not isinstance(msg["transforms"], list):
            raise ValueError(f"transforms is {_kind(msg['transforms'])}, not an array")
        if len(msg["transforms"]) == 1:
            msg = _obj(msg["transforms"][0], "transforms[0]")
    if "header" in msg:
        header = _obj(msg["header"], "header")
        if "stamp" in header:
            _obj(header["stamp"], "header.stamp")
    for parent, keys in (("transform", ("translation", "rotation")), ("pose", ("pose", "position", "orientation")),
                         ("twist", ("twist",))):  # fmt: skip
        if parent in msg:
            _children(_obj(msg[parent], parent), parent, keys)
    if "twist" in msg and isinstance(msg["twist"], dict) and "twist" in msg["twist"]:
        _children(msg["twist"]["twist"], "twist.twist", ("linear", "angular"))
    if "pose" in msg and isinstance(msg["pose"].get("pose"), dict):
        _children(msg["pose"]["pose"], "pose.pose", ("position", "orientation"))


def _children(obj: dict, path: str, keys: tuple[str, ...]) -> None:
    for key in keys:
        if key in obj:
            _obj(obj[key], f"{path}.{key}")


def _obj(value: Any, path: str) -> dict:
    """`value` when it is a JSON object, else a ValueError naming its field path."""
    if isinstance(value, dict):
        return value
    raise ValueError(f"{path} is {_kind(value)}, not an object")


def _kind(value: Any) -> str:
    """A JSON value's kind, as an error names it."""
    if value is None or isinstance(value, bool):
        return json.dumps(value)
    if isinstance(value, (int, float)):
        return "a number"
    return "a string" if isinstance(value, str) else "an array" if isinstance(value, list) else "an object"


def _stamp_parts(stamp: dict) -> tuple[int, int]:
    """header.stamp's (seconds, nanoseconds), ROS 2 or ROS 1 names, when either is not an
    int: a whole float is taken, anything else is an error naming the field."""
    out = []
    for names in (("sec", "secs"), ("nanosec", "nsecs")):
        name = names[0] if names[0] in stamp else names[1]
        value = stamp[name]
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if type(value) is not int:
            raise ValueError(f"header.stamp.{name} is {json.dumps(value)[:40]}, not an integer")
        out.append(value)
    return out[0], out[1]


# The compiled reader of _ODOM_TEXT (classifier/_odomtext.c, built by setup.py where a C
# compiler is): the same (stamp, row) as the regex and float(), 10x faster; None where it
# declines (another layout, wide characters), and the Python path below answers.
try:
    from ._odomtext import odom_fields as _odom_fields_c
    from ._odomtext import odom_rows as _odom_rows_c
except ImportError:  # pragma: no cover - no C compiler at install
    _odom_fields_c = _odom_rows_c = None


def odom_row(msg: dict | str | bytes) -> tuple[int, tuple[float, ...]]:
    """One odometry message (rosbridge dict or JSON text) as (stamp_ns, 13 floats): a
    nav_msgs/Odometry, or a pose without twist (PoseStamped, PoseWithCovarianceStamped,
    TransformStamped, a one-frame TFMessage) whose twist is NaN until `TwistFromPoses` fills it."""
    if isinstance(msg, str):
        if _odom_fields_c is not None and (got := _odom_fields_c(msg)) is not None:
            return got
        return _odom_row_python(msg)
    return _odom_row_parsed(msg)


def odom_rows_compiled(texts: list[str]) -> list[tuple[int, tuple[float, ...]] | None]:
    """The compiled reader's (stamp_ns, row) of each text in one call over the list, None
    where it declines or is not built: `odom_row` then reads that text (and names its error)."""
    return odom_rows_flagged(texts)[0]


def odom_rows_flagged(texts: list[str]) -> tuple[list[tuple[int, tuple[float, ...]] | None], list[int]]:
    """`odom_rows_compiled`, and the positions of the rows that are None or hold a NaN or
    infinite value, found by the compiled reader as it reads (the others need no look in
    Python for values the features cannot use)."""
    if _odom_rows_c is None:  # pragma: no cover - no C compiler at install
        return [None] * len(texts), list(range(len(texts)))
    return _odom_rows_c(texts)


def _odom_row_python(msg: str) -> tuple[int, tuple[float, ...]]:
    """`odom_row` of a text without the compiled reader: the regex, else json.loads."""
    m = _ODOM_TEXT.fullmatch(msg)
    if m is not None:
        g = m.groups()
        return int(g[0]) * NS + int(g[1]), tuple(map(float, g[2:]))
    return _odom_row_parsed(msg)


def _odom_row_parsed(msg: dict | str | bytes) -> tuple[int, tuple[float, ...]]:
    """`odom_row` by json.loads (texts of another layout) or of a rosbridge dict."""
    try:
        if not isinstance(msg, dict):
            msg = json.loads(msg)
        stamp, p, q, twist = _pose_fields(msg)
        sec = stamp["sec"] if "sec" in stamp else stamp["secs"]
        nsec = stamp["nanosec"] if "nanosec" in stamp else stamp["nsecs"]
        sec, nsec = (sec, nsec) if type(sec) is type(nsec) is int else _stamp_parts(stamp)
        v, w = (twist["linear"], twist["angular"]) if twist is not None else (_NAN_XYZ, _NAN_XYZ)
        row = _numbers((p["x"], p["y"], p["z"], q["x"], q["y"], q["z"], q["w"],
                        v["x"], v["y"], v["z"], w["x"], w["y"], w["z"]))  # fmt: skip
        return int(sec) * NS + int(nsec), row if twist is not None else PoseOnly(row)
    except (KeyError, TypeError, ValueError) as err:
        if isinstance(err, TypeError):  # a field that is not an object (null...): name it
            try:
                _pose_fields_checked(msg)
            except ValueError as named:
                err = named
        if isinstance(err, _NotANumber):  # named by its path in this message, not the row's name
            err = ValueError(f"{_message_path(msg, RAW_NAMES[err.index])} is {err.value}, not a number")
        raise InvalidInputError(
            "The message is not a nav_msgs/Odometry, PoseStamped, PoseWithCovarianceStamped or "
            f"TransformStamped in rosbridge JSON (missing or bad field: {err})."
        ) from err


_NAN_XYZ = {"x": float("nan"), "y": float("nan"), "z": float("nan")}


class _NotANumber(ValueError):
    """Row value `index` (of RAW_NAMES) is `value` (JSON, shortened), not a number."""

    def __init__(self, index: int, value: str) -> None:
        super().__init__(f"{RAW_NAMES[index]} is {value}, not a number")
        self.index, self.value = index, value


def _numbers(row: tuple) -> tuple[float, ...]:
    """The row as floats: null is NaN (rosbridge writes NaN so); a string or a list is an
    error naming its field (it was a ValueError traceback when the rows became an array)."""
    try:
        return tuple(float("nan") if v is None else float(v) for v in row)
    except (TypeError, ValueError):
        i = next(i for i, v in enumerate(row) if v is not None and not _is_number(v))
        raise _NotANumber(i, json.dumps(row[i])[:40]) from None


def _message_path(msg: dict, name: str) -> str:
    """RAW_NAMES' `name` (pose.position.x, twist.angular.z) as the path of that value in
    `msg`, walked as `_pose_fields` walks it: an Odometry's x is pose.pose.position.x."""
    prefix = ""
    if "transforms" in msg and "header" not in msg:
        prefix, msg = "transforms[0].", msg["transforms"][0]
    part, group, key = name.split(".")
    if "transform" in msg:
        return f"{prefix}transform.{'translation' if group == 'position' else 'rotation'}.{key}"
    nested = part == "twist" or "pose" in msg["pose"]
    return f"{prefix}{part}.{part + '.' if nested else ''}{group}.{key}"


def _is_number(v) -> bool:
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return True


class PoseOnly(tuple):
    """A raw row read from a message without twist (an odometry's NaN twist is a dropout,
    kept as NaN; this one's is to be derived)."""


def _rotate_back(q: tuple[float, ...], v: tuple[float, float, float]) -> tuple[float, float, float]:
    """v (world frame) in the body frame of orientation q = (x, y, z, w): R(q)^T v."""
    x, y, z, w = q
    vx, vy, vz = v
    # R^T v = v + 2w(v x u)... written out for u = -(x, y, z), the conjugate rotation.
    ux, uy, uz = -x, -y, -z
    tx, ty, tz = 2 * (uy * vz - uz * vy), 2 * (uz * vx - ux * vz), 2 * (ux * vy - uy * vx)
    return (vx + w * tx + (uy * tz - uz * ty), vy + w * ty + (uz * tx - ux * tz), vz + w * tz + (ux * ty - uy * tx))


class TwistFromPoses:
    """Fills the NaN twist of pose-only rows from the previous pose, as odometry reports it:
    linear velocity in the body frame, angular velocity as the rotation between the two
    orientations (body frame) per second. Other rows (with a twist) pass unchanged."""

    def __init__(self) -> None:
        self._last: tuple[int, tuple[float, ...]] | None = None

    def __call__(self, stamp_ns: int, row: tuple[float, ...]) -> tuple[float, ...]:
        if not isinstance(row, PoseOnly):
            return row
        last, self._last = self._last, (stamp_ns, row)
        if last is None or stamp_ns <= last[0]:
            return (*row[:7], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        dt = (stamp_ns - last[0]) / NS
        p0, p1 = last[1], row
        q1 = p1[3:7]
        v = _rotate_back(q1, ((p1[0] - p0[0]) / dt, (p1[1] - p0[1]) / dt, (p1[2] - p0[2]) / dt))
        # q_rel = conj(q0) * q1, the rotation from the last orientation to this one (body frame).
        x0, y0, z0, w0 = -p0[3], -p0[4], -p0[5], p0[6]
        x1, y1, z1, w1 = q1
        rx = w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1
        ry = w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1
        rz = w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1
        rw = w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1
        if rw < 0:  # the short way round
            rx, ry, rz, rw = -rx, -ry, -rz, -rw
        n = (rx * rx + ry * ry + rz * rz) ** 0.5
        k = 2 * atan2(n, rw) / n / dt if n > 1e-12 else 2 / dt
        return (*row[:7], *v, rx * k, ry * k, rz * k)


def parse_odometry(messages: Iterable[dict | str | bytes]) -> OdomArrays:
    """Many odometry messages (dicts or JSON texts) as one OdomArrays; pose-only messages
    get their twist from consecutive poses (`TwistFromPoses`)."""
    stamps: list[int] = []
    rows: list[tuple[float, ...]] = []
    twist = TwistFromPoses()
    for i, msg in enumerate(messages):
        try:
            stamp, row = odom_row(msg)
        except InvalidInputError as err:  # numbered from 1, as `usable` names messages
            raise InvalidInputError(f"Odometry message {i + 1:,}: {err}") from err
        stamps.append(stamp)
        rows.append(twist(stamp, row))
    raw = np.array(rows, dtype=np.float64).reshape(len(rows), RAW_WIDTH)
    return OdomArrays(np.array(stamps, dtype=np.int64), raw)


class FeatureStream(Protocol):
    def push(self, stamp_ns: int, row: Any) -> tuple[np.ndarray, bool] | None: ...


class FeatureSet(Protocol):
    """What a feature set offers: its config, whole-run extraction and live extraction."""

    id: str
    version: int
    params: dict
    dim: int

    def get_config(self) -> dict: ...

    def batch(self, odom: OdomArrays) -> tuple[np.ndarray, np.ndarray]: ...

    def stream(self) -> FeatureStream: ...


class PaperFeatures:
    """The paper's features: raw values of the last `window` messages, every `stride`-th."""

    id = "paper"
    version = 1

    def __init__(self, *, window: int = 500, stride: int = 2):
        if window < 1 or stride < 1 or stride > window:
            raise InvalidInputError(f"Paper features need 1 <= stride <= window, got {window}/{stride}.")
        self.params = {"window": int(window), "stride": int(stride)}
        self.count = window // stride
        self.span = stride * (self.count - 1) + 1
        self.dim = self.count * RAW_WIDTH

    def get_config(self) -> dict:
        return {"id": self.id, "version": self.version, "params": dict(self.params)}

    def batch(self, odom: OdomArrays) -> tuple[np.ndarray, np.ndarray]:
        """(X, valid): row i is NaN and invalid until `span` messages have been seen."""
        n = len(odom)
        X = np.full((n, self.dim), np.nan)
        first = self.span - 1
        if n > first:
            rows = np.arange(first, n)
            offsets = self.params["stride"] * np.arange(self.count - 1, -1, -1)
            X[first:] = odom.raw[rows[:, None] - offsets].reshape(len(rows), self.dim)
        return X, np.arange(n) >= first

    def stream(self) -> _PaperStream:
        return _PaperStream(self)


class _PaperStream:
    def __init__(self, feature_set: PaperFeatures):
        self.stride = feature_set.params["stride"]
        self.rows: deque = deque(maxlen=feature_set.span)

    def push(self, stamp_ns: int, row: Any) -> tuple[np.ndarray, bool] | None:
        """(vector, True) once the window is full, else None."""
        self.rows.append(np.asarray(row, dtype=np.float64))
        if len(self.rows) < self.rows.maxlen:
            return None
        return np.concatenate(list(self.rows)[:: self.stride]), True


# Feature names of the default set, in column order. Each grows with how anomalous the
# motion is and is bounded in nominal driving by the robot's own limits (not by where it
# goes or how fast it chose to drive), so minutes of training cover its nominal range.
DEFAULT_NAMES = (
    "yaw_rate",  # |angular twist z| now, rad/s
    "accel_max",  # max speeding up, d|v|/dt, over the short window, m/s^2 (v3/v4: max |dv/dt|)
    "brake_max",  # max deceleration along the body x axis, m/s^2 (abrupt stops)
    "ang_accel_max",  # max |dw/dt|, rad/s^2 (sudden twisting)
    "lateral_max",  # max |v * w|, m/s^2 (turning harder than the planner allows)
    "reverse_max",  # max backward speed, m/s (a base driven by a planner goes forward)
    "pose_twist_mismatch",  # max |pose displacement - integrated twist| / time, m/s
    "yaw_twist_mismatch",  # max |pose yaw change - integrated yaw rate| / time, rad/s
    "turn_in_place",  # |net rotation while slower than creep_mps|, long window, rad (spinning)
    "yaw_reversals",  # sign changes of the yaw rate beyond +-yaw_flip, last flip_s (oscillation)
    "direction_reversals",  # forward/backward changes beyond +-dir_flip, long window (stuck)
)
# Columns of the short-window maxima (instantaneous values of each message).
_SHORT = slice(1, 8)
# A slow anomaly's lead-in that its gated long columns do not count: the robot slowing into
# a turn in place or a reversal, a stuck robot's stop before its first nudge. On the
# simulator's tuning seeds 1.5 s lost 6 of 144 events that the whole 8 s span kept, 2 s none
# (issue 15, seventh pass, docs/CLASSIFIER.md).
EVIDENCE_LEAD_S = 2.0
# How a pose may have been integrated from the twist (version 6 takes the pose/twist
# mismatch under the scheme that fits best over the window): the mean of the two messages'
# twists (wheel odometry sampled at each stamp), the previous message's (the TUC robot's
# pose; twist differenced forward from the next pose, the slamfail robots) or the current
# one's (TwistFromPoses), each at the step's mid heading. Under the trapezoid alone the
# six long real runs' own odometry "mismatched" by up to 0.24 m/s and 0.28 rad/s over the
# 0.5 s window (3x the limit floors); under the best scheme by at most 0.02 m/s and 0
# rad/s. A slip or a pose jump disagrees under every scheme.
_SCHEMES = ("trapezoid", "previous", "current")


def accepted_rows(t: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """The messages the default features use, by the live stream's rule: a finite message
    whose stamp passes every earlier finite one (a rejected finite stamp never raises that
    maximum). `classifier.usable` names the others."""
    prev_max = np.maximum.accumulate(np.where(finite, t, np.iinfo(np.int64).min))
    accepted = finite.copy()
    accepted[1:] &= t[1:] > prev_max[:-1]
    return accepted


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _window_max(x: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Row i: max of x[start[i] : i+1] (column-wise), by a sparse table (exact, vectorized)."""
    n = len(x)
    if n == 0:
        return x.copy()
    idx = np.arange(n)
    length = idx - start + 1
    level = np.floor(np.log2(length)).astype(np.int64)
    out = np.empty_like(x)
    table = x
    for k in range(int(level.max()) + 1):
        if k:
            half = 1 << (k - 1)
            nxt = table.copy()
            nxt[: n - half] = np.maximum(table[: n - half], table[half:])
            table = nxt
        rows = np.nonzero(level == k)[0]
        if len(rows):
            out[rows] = np.maximum(table[start[rows]], table[rows - (1 << k) + 1])
    return out


class DefaultFeatures:
    """Motion features invariant to position, heading and message rate.

    Derivatives use the actual stamps over a baseline of at least `deriv_s` seconds (so
    jitter and rate change little); windows are in seconds. Messages whose stamp does not
    advance, or with non-finite values, repeat the previous vector. A gap longer than
    `gap_s` restarts everything, and vectors are valid once `warmup_s` of data follow a
    (re)start.
    """

    id = "default"
    version = 6
    names = DEFAULT_NAMES

    def __init__(
        self,
        *,
        deriv_s: float = 0.05,
        match_s: float = 0.5,
        short_s: float = 0.5,
        long_s: float = 8.0,
        flip_s: float = 4.0,
        gap_s: float = 1.0,
        warmup_s: float = 1.0,
        creep_mps: float = 0.1,
        yaw_flip: float = 0.2,
        dir_flip: float = 0.01,
        gate_s: float | None = 1.0,
        despike_s: float | None = 0.1,
        speedup: bool = True,
        any_scheme: bool = True,
    ):
        values = dict(deriv_s=deriv_s, match_s=match_s, short_s=short_s, long_s=long_s,
                      flip_s=flip_s, gap_s=gap_s, warmup_s=warmup_s, creep_mps=creep_mps,
                      yaw_flip=yaw_flip, dir_flip=dir_flip)  # fmt: skip
        # Version 4 gates the long-window features on what happens now (see `_segment`);
        # a version 3 config has neither gate_s nor despike_s and keeps its vectors.
        # Version 5 splits acceleration by sign: `accel_max` is speeding up only, braking
        # stays in `brake_max`, so that the second stage (api.robot_limits) can allow a
        # robot's hard stops at goals without allowing a lurch forward.
        # Version 6 takes the pose/twist mismatch under whichever integration scheme fits
        # best (see `_SCHEMES`).
        if gate_s is not None and despike_s is not None and (speedup or not any_scheme):
            values["gate_s"], values["despike_s"] = gate_s, despike_s
            self.version = 6 if any_scheme else 5 if speedup else 4
        elif gate_s is None and despike_s is None and not speedup and not any_scheme:
            self.version = 3
        else:
            raise InvalidInputError("Feature parameters gate_s and despike_s go together (version 4 on), "
                                    "speedup from version 5, any_scheme from version 6.")  # fmt: skip
        self.speedup, self.any_scheme = speedup, any_scheme
        self.schemes = len(_SCHEMES) if any_scheme else 1
        for name, value in values.items():
            if not value > 0:
                raise InvalidInputError(f"Feature parameter {name} must be > 0, got {value!r}.")
        self.params = {k: float(v) for k, v in values.items()}
        self.dim = len(DEFAULT_NAMES)
        ns = {k: int(round(v * NS)) for k, v in self.params.items() if k.endswith("_s")}
        self._deriv, self._match = ns["deriv_s"], ns["match_s"]
        self._short, self._long = ns["short_s"], ns["long_s"]
        self._gap, self._warmup = ns["gap_s"], ns["warmup_s"]
        self._flip = ns["flip_s"]
        self._gate = ns.get("gate_s")
        self._despike = ns.get("despike_s")
        self.creep, self.yaw_flip, self.dir_flip = creep_mps, yaw_flip, dir_flip
        # How far back each column's evidence reaches (ns): where an anomaly that a column
        # reports may have started, so that its logging window can start there too.
        short_d, short_m = self._short + self._deriv, self._short + self._match
        self.spans_ns = np.array([self._deriv] + [short_d] * 5 + [short_m] * 2
                                 + [self._long, self._flip, self._long], dtype=np.int64)  # fmt: skip
        # The long columns, whose evidence start is tracked (`classifier.evidence`), and
        # how much earlier than their counts it may start: the lead-in that the gated
        # counts do not see (EVIDENCE_LEAD_S) and two despike steps (the gates and flips
        # follow a change that late).
        self.counted = (8, 9, 10)
        self.evidence_margin_ns = int(EVIDENCE_LEAD_S * NS) + 2 * (self._despike or 0)
        # How far back the newest vector looks: a window plus the baseline of its oldest row.
        self.horizon_ns = max(self._short + self._deriv, self._short + self._match, self._long,
                              self._flip)  # fmt: skip

    def get_config(self) -> dict:
        return {"id": self.id, "version": self.version, "params": dict(self.params)}

    def batch(self, odom: OdomArrays) -> tuple[np.ndarray, np.ndarray]:
        """(X, valid) for a whole run: one vector per message."""
        n = len(odom)
        X = np.full((n, self.dim), np.nan)
        valid = np.zeros(n, dtype=bool)
        t = odom.stamp_ns
        if n == 0:
            return X, valid
        acc_idx = np.nonzero(accepted_rows(t, np.isfinite(odom.raw).all(axis=1)))[0]
        if len(acc_idx) == 0:
            return X, valid
        ta = t[acc_idx]
        breaks = np.nonzero(np.diff(ta) > self._gap)[0] + 1
        bounds = np.concatenate([[0], breaks, [len(ta)]])
        Xa = np.empty((len(ta), self.dim))
        va = np.empty(len(ta), dtype=bool)
        for a, b in zip(bounds[:-1], bounds[1:]):
            sel = acc_idx[a:b]
            Xa[a:b], va[a:b] = self._segment(t[sel], odom.raw[sel], int(t[sel[0]]))
        # Every message gets the vector of the newest accepted message at or before it.
        owner = np.searchsorted(acc_idx, np.arange(n), side="right") - 1
        has = owner >= 0
        X[has] = Xa[owner[has]]
        valid[has] = va[owner[has]]
        return X, valid

    def stream(self) -> _DefaultStream | _CompiledDefaultStream:
        return _DefaultStream(self) if _Stream is None else _CompiledDefaultStream(self)

    def _segment(self, t: np.ndarray, raw: np.ndarray, seg_start: int):
        """Vectors of one gap-free run with strictly increasing stamps `t` (int64 ns).

        `_DefaultStream` computes the same values message by message: change both alike.
        Kept as one function, in the same order as `_DefaultStream.push`, so that the two
        can be compared line by line.
        """
        n = len(t)
        pos = raw[:, 0:2]
        qx, qy, qz, qw = raw[:, 3], raw[:, 4], raw[:, 5], raw[:, 6]
        yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        vx, vy, wz = raw[:, 7], raw[:, 8], raw[:, 12]
        # Integrals use the twist as reported; rates, accelerations and flips use it
        # despiked (version 4, see `_despiked`).
        fvx, fvy, fwz = self._despiked(t, vx, vy, wz)
        speed = np.hypot(fvx, fvy)

        # Step integrals between consecutive messages (trapezoid, mid-step heading).
        dt = np.diff(t) * 1e-9
        dyaw = _wrap(np.diff(yaw))
        mid = yaw[:-1] + 0.5 * dyaw
        mvx, mvy = 0.5 * (vx[1:] + vx[:-1]), 0.5 * (vy[1:] + vy[:-1])
        mw = 0.5 * (wz[1:] + wz[:-1])
        c, s = np.cos(mid), np.sin(mid)
        # Columns 0, 1: pose yaw change (unwrapped by summing wrapped steps), turning in
        # place; then per integration scheme (`_SCHEMES`) the twist-integrated world x, y, yaw.
        twists = ((mvx, mvy, mw), (vx[:-1], vy[:-1], wz[:-1]), (vx[1:], vy[1:], wz[1:]))
        cols = [dyaw, np.where(np.hypot(mvx, mvy) < self.creep, mw * dt, 0.0)]
        for ux, uy, uw in twists[: self.schemes]:
            cols += [(c * ux - s * uy) * dt, (s * ux + c * uy) * dt, uw * dt]
        steps = np.column_stack(cols)
        cum = np.zeros((n, steps.shape[1]))
        np.cumsum(steps, axis=0, out=cum[1:])

        def back(lag: int) -> tuple[np.ndarray, np.ndarray]:
            """Baseline rows at least `lag` ns back (clamped to the run start), and the times."""
            k = np.maximum(np.searchsorted(t, t - lag, side="right") - 1, 0)
            span = (t - t[k]) * 1e-9
            return k, np.where(span > 0, span, np.inf)

        k, span = back(self._deriv)
        ax = (fvx - fvx[k]) / span
        accel = (speed - speed[k]) / span if self.speedup else np.hypot(ax, (fvy - fvy[k]) / span)
        alpha = np.abs((fwz - fwz[k]) / span)
        m, mspan = back(self._match)
        dpose, dcum = pos - pos[m], cum - cum[m]
        mis_lin = np.min([np.hypot(dpose[:, 0] - dcum[:, k], dpose[:, 1] - dcum[:, k + 1])
                          for k in range(2, dcum.shape[1], 3)], axis=0) / mspan  # fmt: skip
        mis_yaw = np.min([np.abs(dcum[:, 0] - dcum[:, k]) for k in range(4, dcum.shape[1], 3)], axis=0) / mspan
        inst = np.column_stack([accel, -ax, alpha, speed * np.abs(fwz), -fvx, mis_lin, mis_yaw])
        short = _window_max(inst, np.searchsorted(t, t - self._short, side="left"))
        short[:, 4] = np.maximum(short[:, 4], 0.0)  # reverse speed: none is 0, not -speed
        if self.speedup:
            short[:, 0] = np.maximum(short[:, 0], 0.0)  # only slowing down: 0

        j = np.searchsorted(t, t - self._long, side="left")
        f = np.searchsorted(t, t - self._flip, side="left")
        yflip, dflip = _flips(fwz, self.yaw_flip), _flips(fvx, self.dir_flip)
        yaw_flips = np.concatenate(([0], np.cumsum(yflip)))
        dir_flips = np.concatenate(([0], np.cumsum(dflip)))
        idx = np.arange(n) + 1
        X = np.column_stack([
            np.abs(fwz), short, np.abs(cum[:, 1] - cum[j, 1]),
            yaw_flips[idx] - yaw_flips[f], dir_flips[idx] - dir_flips[j],
        ])  # fmt: skip
        if self._gate is not None:
            # The long windows say how much happened over seconds; gated, they speak only
            # while it still happens, so a score falls within gate_s of an event's end
            # and a logging window can close soon after it.
            X[:, 8] *= (speed < self.creep) & (np.abs(fwz) > self.yaw_flip)
            X[:, 9:11] *= np.column_stack([_recent(t, f, self._gate) for f in (yflip, dflip)])
        return X, t - seg_start >= self._warmup

    def _despiked(self, t: np.ndarray, *columns: np.ndarray) -> tuple[np.ndarray, ...]:
        """Real odometry has one-message glitches (a wheel speed that drops by 0.4 m/s for
        one message and is back at the next, 20 in the 23 min of tuc_lecture_hall) that no
        body can follow. The median of the values now, despike_s ago and twice that ago
        removes them at any message rate (version 3: the columns unchanged)."""
        if self._despike is None:
            return columns
        k1 = np.maximum(np.searchsorted(t, t - self._despike, side="right") - 1, 0)
        k2 = np.maximum(np.searchsorted(t, t - 2 * self._despike, side="right") - 1, 0)
        return tuple(_median3(c[k2], c[k1], c) for c in columns)


def _flips(x: np.ndarray, h: float) -> np.ndarray:
    """1.0 where x changes sign with hysteresis: beyond +-h, opposite to the last value
    beyond +-h (0.0 at the first such value and elsewhere)."""
    n = len(x)
    last = np.maximum.accumulate(np.where(np.abs(x) > h, np.arange(n), -1))
    state = np.where(last >= 0, np.sign(x[np.maximum(last, 0)]), 0.0)
    out = np.zeros(n)
    out[1:] = (state[1:] != state[:-1]) & (state[:-1] != 0)
    return out


def _median3(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Element-wise median of three arrays."""
    return np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))


def _recent(t: np.ndarray, flips: np.ndarray, within: int) -> np.ndarray:
    """True where the newest flip at or before each row is at most `within` ns old."""
    last = np.maximum.accumulate(np.where(flips > 0, np.arange(len(t)), -1))
    return (last >= 0) & (t - t[np.maximum(last, 0)] <= within)


class _DefaultStream:
    """Live extraction in O(1) per message: running sums, baseline queues, running maxima
    (monotonic deques) and flip queues give the same vector `DefaultFeatures._segment`
    computes for the newest row.

    This runs once per live odometry message, so it works on plain floats and tuples
    with the queue helpers written out inline (method calls and numpy scalars cost more
    here than the arithmetic).
    """

    def __init__(self, feature_set: DefaultFeatures):
        self.feature_set = f = feature_set
        self.deriv_ns, self.match_ns, self.short_ns = f._deriv, f._match, f._short
        self.long_ns, self.flip_ns, self.gap_ns, self.warmup_ns = f._long, f._flip, f._gap, f._warmup
        self.gate_ns, self.despike_ns = f._gate, f._despike
        self.speedup = f.speedup
        self.last: tuple[np.ndarray, bool] | None = None
        self.prev: tuple | None = None  # (t, yaw, vx, vy, wz) of the last accepted message
        self._reset()

    def _reset(self) -> None:
        self.prev = None
        # (t, vx, vy, wz) baselines despike_s and 2 x despike_s back, for the despike median
        self.held1: deque = deque()
        self.held2: deque = deque()
        self.seg_start = 0
        self.cum = (0.0,) * 5
        # Cumulative world x, y, yaw under the "previous" and "current" schemes (version 6).
        self.ext = (0.0,) * 6 if self.feature_set.any_scheme else None
        self.deriv: deque = deque()  # (t, vx, vy, wz): the baseline is the first entry
        self.match: deque = deque()  # (t, x, y, cum0, cum1, cum2, cum3, ext)
        self.long: deque = deque()  # (t, cum4)
        # Short-window maxima of each instantaneous value: (t, v), v decreasing.
        self.maxima = tuple(deque() for _ in range(_SHORT.stop - _SHORT.start))
        # `_flips` live: the last sign beyond +-h and the stamps of flips still counted.
        self.yaw_state = self.dir_state = 0
        self.yaw_q: deque = deque()
        self.dir_q: deque = deque()

    def push(self, stamp_ns: int, row: Any) -> tuple[np.ndarray, bool] | None:
        """Vector and validity after this message (None before the first usable message).

        One long function on purpose: it runs once per odometry message on the robot, with
        every queue and state in locals (live p99 target < 1 ms, `python3 dev.py bench
        classifier_speed`); it mirrors `DefaultFeatures._segment` step by step, so the two
        can be read side by side (tests check they agree to 1e-9).
        """
        if type(row) is not tuple and type(row) is not list:
            row = row.tolist() if isinstance(row, np.ndarray) else [float(v) for v in row]
        if not isfinite(sum(row)) and not all(isfinite(v) for v in row):
            return self.last
        prev = self.prev
        t = stamp_ns
        if prev is not None:
            if t <= prev[0]:
                return self.last
            if t - prev[0] > self.gap_ns:
                self._reset()
                prev = None
        x, y, _, qx, qy, qz, qw, vx, vy, _, _, _, wz = row
        yaw = atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        c0, c1, c2, c3, c4 = self.cum
        if prev is None:
            self.seg_start = t
        else:
            pt, pyaw, pvx, pvy, pwz = prev
            dt = (t - pt) * 1e-9
            dyaw = (yaw - pyaw + pi) % TWO_PI - pi
            mid = pyaw + 0.5 * dyaw
            mvx, mvy, mw = 0.5 * (vx + pvx), 0.5 * (vy + pvy), 0.5 * (wz + pwz)
            c, s = cos(mid), sin(mid)
            c0 += (c * mvx - s * mvy) * dt
            c1 += (s * mvx + c * mvy) * dt
            c2 += mw * dt
            c3 += dyaw
            if hypot(mvx, mvy) < self.feature_set.creep:
                c4 += mw * dt
            self.cum = (c0, c1, c2, c3, c4)
            if self.ext is not None:  # the other integration schemes (`_SCHEMES`)
                e0, e1, e2, e3, e4, e5 = self.ext
                self.ext = (e0 + (c * pvx - s * pvy) * dt, e1 + (s * pvx + c * pvy) * dt, e2 + pwz * dt,
                            e3 + (c * vx - s * vy) * dt, e4 + (s * vx + c * vy) * dt, e5 + wz * dt)  # fmt: skip
        self.prev = (t, yaw, vx, vy, wz)
        if self.despike_ns is not None:  # as in `_segment`: from here on, the despiked twist
            now = (t, vx, vy, wz)
            for q, lag in ((self.held1, self.despike_ns), (self.held2, 2 * self.despike_ns)):
                q.append(now)
                while len(q) > 1 and q[1][0] <= t - lag:
                    q.popleft()
            a, b = self.held2[0], self.held1[0]
            vx, vy, wz = (max(min(a[i], b[i]), min(max(a[i], b[i]), now[i])) for i in (1, 2, 3))

        # Baselines: the newest entry at least `lag` back, else the segment's first.
        d = self.deriv
        d.append((t, vx, vy, wz))
        bound = t - self.deriv_ns
        while len(d) > 1 and d[1][0] <= bound:
            d.popleft()
        kt, kvx, kvy, kwz = d[0]
        span = (t - kt) * 1e-9 if t > kt else inf
        ax = (vx - kvx) / span
        m = self.match
        ext = self.ext
        m.append((t, x, y, c0, c1, c2, c3, ext))
        bound = t - self.match_ns
        while len(m) > 1 and m[1][0] <= bound:
            m.popleft()
        mt, mx, my, m0, m1, m2, m3, mext = m[0]
        mspan = (t - mt) * 1e-9 if t > mt else inf
        px, py, pose_turn = x - mx, y - my, c3 - m3  # pose change over the match window
        mis = hypot(px - (c0 - m0), py - (c1 - m1))
        ymis = abs(pose_turn - (c2 - m2))
        if ext is not None:
            for k in (0, 3):
                mis = min(mis, hypot(px - (ext[k] - mext[k]), py - (ext[k + 1] - mext[k + 1])))
                ymis = min(ymis, abs(pose_turn - (ext[k + 2] - mext[k + 2])))
        inst = (
            (hypot(vx, vy) - hypot(kvx, kvy)) / span if self.speedup else hypot(ax, (vy - kvy) / span),  # accel
            -ax,  # brake
            abs((wz - kwz) / span),  # angular acceleration
            hypot(vx, vy) * abs(wz),  # lateral
            -vx,  # reverse
            mis / mspan,  # pose/twist mismatch
            ymis / mspan,  # yaw mismatch
        )
        vec = [abs(wz)]
        bound = t - self.short_ns
        for q, v in zip(self.maxima, inst):
            while q and q[-1][1] <= v:
                q.pop()
            q.append((t, v))
            while q[0][0] < bound:
                q.popleft()
            vec.append(q[0][1])
        if vec[5] < 0.0:
            vec[5] = 0.0  # reverse speed: none is 0, not -speed
        if vec[1] < 0.0 and self.speedup:
            vec[1] = 0.0  # only slowing down: 0

        lq = self.long
        lq.append((t, c4))
        bound = t - self.long_ns
        while lq[0][0] < bound:
            lq.popleft()
        gate = self.gate_ns
        if gate is None or (hypot(vx, vy) < self.feature_set.creep and abs(wz) > self.feature_set.yaw_flip):
            vec.append(abs(c4 - lq[0][1]))
        else:
            vec.append(0.0)
        # The two reversal counters below are written out rather than shared: on this path a
        # call per message costs more than the counting (the inlining took push from 4.41 to
        # 3.64 us a message).
        h = self.feature_set.yaw_flip
        if wz > h or wz < -h:
            sign = 1 if wz > 0 else -1
            if self.yaw_state and sign != self.yaw_state:
                self.yaw_q.append(t)
            self.yaw_state = sign
        q = self.yaw_q
        bound = t - self.flip_ns
        while q and q[0] < bound:
            q.popleft()
        vec.append(len(q) if gate is None or (q and t - q[-1] <= gate) else 0)
        h = self.feature_set.dir_flip
        if vx > h or vx < -h:
            sign = 1 if vx > 0 else -1
            if self.dir_state and sign != self.dir_state:
                self.dir_q.append(t)
            self.dir_state = sign
        q = self.dir_q
        bound = t - self.long_ns
        while q and q[0] < bound:
            q.popleft()
        vec.append(len(q) if gate is None or (q and t - q[-1] <= gate) else 0)
        self.last = (np.array(vec, dtype=np.float64), t - self.seg_start >= self.warmup_ns)
        return self.last


# The compiled live stream (classifier/_stream.c, built by setup.py where a C compiler
# is): `_DefaultStream.push` step for step, the same doubles, 0.6 instead of 5 us a message.
try:
    from ._stream import Stream as _Stream
except ImportError:  # pragma: no cover - no C compiler at install
    _Stream = None


class _CompiledDefaultStream:
    """`_DefaultStream` by the compiled helper: `push` gives the same (vector, valid).
    `values` gives the vector as a tuple of floats, for callers that stack many vectors
    into one array anyway (SmartLogger), sparing an array per message."""

    def __init__(self, feature_set: DefaultFeatures):
        f = feature_set
        ns = (f._deriv, f._match, f._short, f._long, f._flip, f._gap, f._warmup,
              -1 if f._gate is None else f._gate, -1 if f._despike is None else f._despike)  # fmt: skip
        self._c = _Stream(ns, (f.creep, f.yaw_flip, f.dir_flip), (f.speedup, f.any_scheme), hypot)
        self.values = self._c.push
        self._got = None
        self.last: tuple[np.ndarray, bool] | None = None

    def push(self, stamp_ns: int, row: Any) -> tuple[np.ndarray, bool] | None:
        got = self._c.push(stamp_ns, row)
        if got is not self._got:  # a skipped message gives the last vector again, the same object
            self._got = got
            self.last = None if got is None else (np.array(got[0], dtype=np.float64), got[1])
        return self.last


FEATURE_SETS = {"default": DefaultFeatures, "paper": PaperFeatures}


def make_features(config: dict | str | None = None) -> DefaultFeatures | PaperFeatures:
    """A feature set from its config dict ({"id", "version", "params"}) or id."""
    if config is None:
        config = "default"
    if isinstance(config, str):
        config = {"id": config}
    fid = config.get("id")
    if fid not in FEATURE_SETS:
        raise InvalidInputError(
            f"Unknown feature set {fid!r}; known: {', '.join(sorted(FEATURE_SETS))}."
        )
    cls = FEATURE_SETS[fid]
    version = config.get("version", cls.version)
    params = dict(config.get("params", {}))
    if fid == "default" and version == 3 and not {"gate_s", "despike_s"} & set(params):
        old = {"gate_s": None, "despike_s": None, "speedup": False, "any_scheme": False}
        return _make(cls, fid, params | old)  # older models
    if fid == "default" and version == 4 and {"gate_s", "despike_s"} <= set(params):
        return _make(cls, fid, params | {"speedup": False, "any_scheme": False})  # issue 15's first pass
    if fid == "default" and version == 5 and {"gate_s", "despike_s"} <= set(params):
        return _make(cls, fid, params | {"any_scheme": False})  # issue 15's second pass
    if version != cls.version:
        raise InvalidInputError(
            f"Feature set {fid!r} version {version} is not supported (this is version {cls.version})."
        )
    return _make(cls, fid, params)


def _make(cls, fid: str, params: dict):
    try:
        return cls(**params)
    except TypeError as err:
        raise InvalidInputError(f"Bad parameters for feature set {fid!r}: {err}.") from err
