"""`simulate()` and its result, `SimRun`: arrays, message texts, labels, and writers."""

from __future__ import annotations

import json
import math
import numbers
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import InvalidInputError
from .anomalies import KINDS, Event, motion_overrides, schedule_events, sensor_extras
from .drive import RobotParams, drive
from .messages import IMU, ODOM, TF, TYPESTORE, TopicSpec
from .sensors import Calibration, ImuData, imu, odometry, sample_times
from .world import build_building

__all__ = ["DEFAULT_START_NS", "HEADINGS", "SimRun", "simulate"]

# Header stamps start here (22 May 2015, the era of the paper's BWIBot logs).
DEFAULT_START_NS = 1_432_235_695_000_000_000
_TOPICS: dict[str, TopicSpec] = {"/odom": ODOM, "/imu": IMU, "/tf": TF}
MAX_DURATION_S = 24 * 3600.0
HEADINGS = ("wheels", "imu")
_ROBOT_STREAM = 0x524F424F  # "ROBO": keeps robot draws apart from SeedSequence(seed)'s


@dataclass
class SimRun:
    """A simulated run. Arrays have one entry per /odom message (reported values unless
    `true_*`); `events` are the injected anomalies; `labels[i]` is 0 for nominal or
    1 + index in `KINDS` of the event covering message i."""

    config: dict
    stamp_ns: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    vx: np.ndarray
    wz: np.ndarray
    true_x: np.ndarray
    true_y: np.ndarray
    true_yaw: np.ndarray
    true_v: np.ndarray
    true_w: np.ndarray
    imu: ImuData
    events: list[Event]
    labels: np.ndarray = field(repr=False)

    @property
    def qz(self) -> np.ndarray:
        return np.sin(0.5 * self.yaw)

    @property
    def qw(self) -> np.ndarray:
        return np.cos(0.5 * self.yaw)

    @property
    def anomalous(self) -> np.ndarray:
        """Boolean mask: the message lies inside an injected anomaly."""
        return self.labels > 0

    def __len__(self) -> int:
        return len(self.stamp_ns)

    @cached_property
    def messages(self) -> list[tuple[int, str]]:
        """/odom as (stamp_ns, rosbridge JSON text)."""
        return self.topic_messages("/odom")

    def topic_messages(self, topic: str) -> list[tuple[int, str]]:
        """(stamp_ns, JSON text) of one topic: "/odom", "/imu" or "/tf"."""
        spec = _spec(topic)
        return list(zip(self.stamp_ns.tolist(), spec.texts(self._columns(topic))))

    def ros_messages(self, topic: str) -> list:
        """rosbags message objects of one topic (what the bag holds)."""
        return _spec(topic).messages(self._columns(topic))

    def _arrays(self, topic: str) -> dict[str, np.ndarray]:
        """The per-field arrays that fill the topic's message template."""
        sec, nanosec = np.divmod(self.stamp_ns, 1_000_000_000)
        cols: dict[str, np.ndarray] = {"sec": sec, "nanosec": nanosec}
        if topic == "/imu":
            cols.update(qz=np.sin(0.5 * self.imu.yaw), qw=np.cos(0.5 * self.imu.yaw),
                        gz=self.imu.gz, ax=self.imu.ax, ay=self.imu.ay, az=self.imu.az)
        else:
            cols.update(x=self.x, y=self.y, qz=self.qz, qw=self.qw)
            if topic == "/odom":
                cols.update(vx=self.vx, wz=self.wz)
        return cols

    def _columns(self, topic: str) -> dict[str, list]:
        # Python ints and floats: their repr is what json.dumps writes
        return {k: v.tolist() for k, v in self._arrays(topic).items()}

    def labels_dict(self) -> dict:
        """The labels file: events plus the run's configuration."""
        return {"events": [e.to_dict() for e in self.events], "run": self.config}

    def write(
        self, out_dir: str | os.PathLike, *, imu: bool = False, tf: bool = False
    ) -> dict[str, Path]:
        """Write out_dir/run (rosbag2, MCAP), out_dir/labels.json and out_dir/run.jsonl."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        topics = ["/odom"] + (["/imu"] if imu else []) + (["/tf"] if tf else [])
        paths = {"bag": out / "run", "labels": out / "labels.json", "jsonl": out / "run.jsonl"}
        for p in paths.values():
            if p.exists():
                raise InvalidInputError(
                    f"{p} exists already; write the run into an empty directory."
                )
        self.write_bag(paths["bag"], topics=topics)
        self.write_labels(paths["labels"])
        self.write_jsonl(paths["jsonl"], topics=topics)
        return paths

    def write_labels(self, path: str | os.PathLike) -> None:
        Path(path).write_text(json.dumps(self.labels_dict(), indent=1) + "\n", encoding="utf-8")

    def write_jsonl(self, path: str | os.PathLike, *, topics: Sequence[str] = ("/odom",)) -> None:
        """One `{"topic", "stamp_ns", "msg"}` object per line, in time order."""
        with open(path, "w", encoding="utf-8") as f:
            for line in self._interleave(topics):
                f.write(line)

    def _interleave(self, topics: Sequence[str]) -> Iterable[str]:
        stamps = self.stamp_ns.tolist()
        per_topic = [(t, _spec(t).texts(self._columns(t))) for t in topics]
        for i, ns in enumerate(stamps):
            for topic, texts in per_topic:
                yield f'{{"topic": "{topic}", "stamp_ns": {ns}, "msg": {texts[i]}}}\n'

    def write_bag(self, path: str | os.PathLike, *, topics: Sequence[str] = ("/odom",)) -> None:
        """A rosbag2 directory with MCAP storage, messages as CDR, log time = header stamp.

        The CDR comes from a byte template (see messages.py); the tests check it against
        rosbags' serialize_cdr and read it back."""
        from rosbags.rosbag2 import StoragePlugin, Writer

        stamps = self.stamp_ns.tolist()
        with Writer(Path(path), version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = []
            for topic in topics:
                spec = _spec(topic)
                conn = writer.add_connection(topic, spec.msgtype, typestore=TYPESTORE)
                conns.append((conn, spec.cdr(self._arrays(topic))))
            for i, ns in enumerate(stamps):
                for conn, raws in conns:
                    writer.write(conn, ns, raws[i])

    def summary(self) -> str:
        """A few human-readable lines about the run."""
        c = self.config
        dist = float(np.sum(np.hypot(np.diff(self.true_x), np.diff(self.true_y))))
        lines = [
            f"{len(self)} /odom messages, {c['duration_s']:g} s at {c['rate_hz']:g} Hz, "
            f"seed {c['seed']}, {dist:.0f} m driven, {c['goals_reached']} goals reached",
            f"{len(self.events)} anomalies covering {self.anomalous.mean() * 100:.1f}% of messages",
        ]
        for e in self.events:
            lines.append(
                f"  {e.start_s:8.2f}-{e.end_s:8.2f} s  {e.kind:<20} severity {e.severity:.2f}"
            )
        return "\n".join(lines)


def _spec(topic: str) -> TopicSpec:
    try:
        return _TOPICS[topic]
    except KeyError:
        raise InvalidInputError(
            f"topic {topic!r} is not simulated; choose one of {', '.join(_TOPICS)}."
        ) from None


def _check(
    seed: object, duration_s: float, rate_hz: float, anomalies: object,
    anomaly_rate_per_min: float | None, kinds: Sequence[str] | None, severity: Sequence[float],
) -> tuple[str, ...]:
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise InvalidInputError(f"seed must be a non-negative integer, not {seed!r}.")
    if not (isinstance(duration_s, numbers.Real) and math.isfinite(duration_s)
            and 0 < duration_s <= MAX_DURATION_S):
        raise InvalidInputError(
            f"duration_s must be a number of seconds in (0, {MAX_DURATION_S:g}], "
            f"not {duration_s!r}."
        )
    if not (isinstance(rate_hz, numbers.Real) and math.isfinite(rate_hz) and 1 <= rate_hz <= 1000):
        raise InvalidInputError(f"rate_hz must be between 1 and 1000 Hz, not {rate_hz!r}.")
    if duration_s * rate_hz < 2:
        raise InvalidInputError(
            f"a {duration_s:g} s run at {rate_hz:g} Hz has fewer than 2 messages; make it longer."
        )
    if isinstance(anomalies, bool) or not isinstance(anomalies, numbers.Integral) or anomalies < 0:
        raise InvalidInputError(
            f"anomalies must be a non-negative integer count, not {anomalies!r}."
        )
    if anomaly_rate_per_min is not None and not (
        isinstance(anomaly_rate_per_min, numbers.Real) and 0 <= anomaly_rate_per_min < 1000
    ):
        raise InvalidInputError(
            f"anomaly_rate_per_min must be a non-negative number, not {anomaly_rate_per_min!r}."
        )
    if len(severity) != 2:
        raise InvalidInputError(f"severity must be a (low, high) pair, not {severity!r}.")
    lo, hi = severity
    if not (0 < lo <= hi <= 5):
        raise InvalidInputError(
            f"severity range ({lo!r}, {hi!r}) must satisfy 0 < low <= high <= 5 "
            "(1.0 is the default)."
        )
    chosen = tuple(kinds) if kinds is not None else KINDS
    if isinstance(kinds, str) or not chosen:
        raise InvalidInputError(f"kinds must be a non-empty list of anomaly kinds, not {kinds!r}.")
    unknown = [k for k in chosen if k not in KINDS]
    if unknown:
        raise InvalidInputError(
            f"unknown anomaly kind(s) {', '.join(map(repr, unknown))}; known: {', '.join(KINDS)}."
        )
    return chosen


def _check_robot(robot_seed: object, heading: str, start_ns: object, duration_s: float) -> None:
    """The arguments that pick the robot and the clock; see `simulate`."""
    if robot_seed is not None and (isinstance(robot_seed, bool) or not isinstance(
            robot_seed, numbers.Integral) or robot_seed < 0):
        raise InvalidInputError(
            f"robot_seed must be a non-negative integer or None, not {robot_seed!r}."
        )
    if heading not in HEADINGS:
        raise InvalidInputError(
            f"heading must be one of {', '.join(map(repr, HEADINGS))}, not {heading!r}."
        )
    if isinstance(start_ns, bool) or not isinstance(start_ns, numbers.Integral) or not (
        0 <= start_ns and start_ns + duration_s * 1e9 + 1e9 < 2**31 * 1e9
    ):
        raise InvalidInputError(
            f"start_ns must be a non-negative integer such that the run ends before 2**31 s "
            f"(header stamps hold seconds as int32), not {start_ns!r}."
        )


def _robot(r_params: np.random.Generator, robot_seed: int | None) -> tuple[RobotParams, Calibration | None]:
    """The robot's limits and odometry calibration: drawn from the run's stream, or fixed
    by `robot_seed` (the same robot on different days). The run's draw happens either way,
    so a run's other random streams do not depend on robot_seed."""
    a_max = float(r_params.uniform(0.55, 1.0))
    calibration = None
    if robot_seed is not None:
        r_robot = np.random.default_rng([int(robot_seed), _ROBOT_STREAM])
        a_max = float(r_robot.uniform(0.55, 1.0))
        calibration = Calibration(*(1.0 + r_robot.normal(0.0, 0.002, 2)),
                                  1.0 + float(r_robot.normal(0.0, 0.003)))
    return RobotParams(a_max=a_max), calibration


def _labels(events, stamp_ns: np.ndarray) -> np.ndarray:
    """Per message: 0 nominal, else 1 + the index in KINDS of the event it falls in."""
    labels = np.zeros(len(stamp_ns), np.int8)
    for e in events:
        i0, i1 = np.searchsorted(stamp_ns, [e.start_ns, e.end_ns])
        labels[i0:i1] = KINDS.index(e.kind) + 1
    return labels


def simulate(
    *,
    seed: int = 0,
    duration_s: float = 60.0,
    rate_hz: float = 100.0,
    anomalies: int = 0,
    anomaly_rate_per_min: float | None = None,
    kinds: Sequence[str] | None = None,
    severity: Sequence[float] = (0.5, 1.5),
    start_ns: int = DEFAULT_START_NS,
    robot_seed: int | None = None,
    heading: str = "wheels",
) -> SimRun:
    """Simulate a run; `anomalies=0` (the default) is a nominal run.

    `anomalies` is an exact count (an error if they do not fit); `anomaly_rate_per_min`,
    when given, replaces it by a Poisson count at that rate (capped to what fits).
    `kinds` restricts the kinds (default all of KINDS, used in turn); each event's
    severity is drawn uniformly from `severity`.

    `robot_seed` fixes the robot: its acceleration limit and odometry calibration (wheel
    scale errors, wheel-base estimate) come from it instead of from `seed`, so runs with
    different seeds but one robot_seed are the same robot on different days. `heading`
    "imu" publishes the IMU's heading as the odometry yaw (Kobuki's use_imu_heading, or an
    EKF trusting the gyro for yaw) while the twist stays from the wheels: wheel slip then
    shows as a yaw rate that the pose does not follow. The defaults give today's runs.
    """
    chosen = _check(seed, duration_s, rate_hz, anomalies, anomaly_rate_per_min, kinds, severity)
    _check_robot(robot_seed, heading, start_ns, duration_s)
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(6)]
    r_sched, r_drive, r_time, r_odom, r_imu, r_params = streams
    lo, hi = float(severity[0]), float(severity[1])
    strict = anomaly_rate_per_min is None
    if strict:
        count = int(anomalies)
    else:
        count = int(r_sched.poisson(anomaly_rate_per_min * duration_s / 60.0))
    events = schedule_events(r_sched, duration_s=float(duration_s), start_ns=int(start_ns),
                             count=count, kinds=chosen, severity=(lo, hi), strict=strict)

    params, calibration = _robot(r_params, robot_seed)
    n_out = int(round(duration_s * rate_hz))
    t = sample_times(r_time, n_out, float(rate_hz))
    dt = 1.0 / max(100.0, float(rate_hz))
    n_int = int(math.ceil(t[-1] / dt)) + 2
    building = build_building()
    truth = drive(r_drive, building, params, n_int, dt,
                  motion_overrides(events, n_int, dt, params.a_max))
    tt = np.arange(n_int) * dt
    true_x, true_y = np.interp(t, tt, truth.x), np.interp(t, tt, truth.y)
    true_yaw = np.interp(t, tt, truth.yaw)
    imu_data = imu(r_imu, truth, t)
    rep = odometry(r_odom, truth, t, params.wheel_base, float(truth.x[0]), float(truth.y[0]),
                   float(truth.yaw[0]), sensor_extras(events, t), calibration=calibration,
                   heading=np.unwrap(imu_data.yaw) if heading == "imu" else None)
    stamp_ns = int(start_ns) + np.round(t * 1e9).astype(np.int64)

    labels = _labels(events, stamp_ns)
    config = {
        "seed": int(seed), "duration_s": float(duration_s), "rate_hz": float(rate_hz),
        "start_ns": int(start_ns), "severity": [lo, hi], "kinds": list(chosen),
        "anomalies_requested": count, "a_max": params.a_max, "goals_reached": truth.goals,
    }
    if robot_seed is not None:  # only when asked for, so default runs keep their bytes
        config["robot_seed"] = int(robot_seed)
    if heading != "wheels":
        config["heading"] = heading
    return SimRun(
        config=config, stamp_ns=stamp_ns, x=rep.x, y=rep.y, yaw=rep.yaw, vx=rep.vx, wz=rep.wz,
        true_x=true_x, true_y=true_y, true_yaw=(true_yaw + np.pi) % (2 * np.pi) - np.pi,
        true_v=np.interp(t, tt, truth.v), true_w=np.interp(t, tt, truth.w),
        imu=imu_data, events=events, labels=labels,
    )
