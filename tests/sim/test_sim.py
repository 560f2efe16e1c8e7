"""The simulator: determinism, labels that match the disturbance, bags, JSON, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from cclogfs.cli import main
from cclogfs.errors import InvalidInputError
from cclogfs.jsontext.ros import message_stamp_ns, message_to_json
from cclogfs.sim import KIND_GROUPS, KINDS, simulate


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _window(run, ev, pad_s=0.0):
    pad = int(pad_s * 1e9)
    return (run.stamp_ns >= ev.start_ns - pad) & (run.stamp_ns < ev.end_ns + pad)


def _accel(run):
    t = (run.stamp_ns - run.stamp_ns[0]) / 1e9
    return np.gradient(run.true_v, t)


# --- determinism ---------------------------------------------------------------------

def test_same_seed_same_bytes(tmp_path):
    kw = dict(seed=7, duration_s=60, rate_hz=100, anomalies=3)
    simulate(**kw).write(tmp_path / "a", imu=True, tf=True)
    simulate(**kw).write(tmp_path / "b", imu=True, tf=True)
    a, b = _files(tmp_path / "a"), _files(tmp_path / "b")
    assert set(a) == {"labels.json", "run.jsonl", "run/metadata.yaml", "run/run.mcap"}
    assert a == b


def test_other_seed_other_run():
    a = simulate(seed=1, duration_s=30)
    b = simulate(seed=2, duration_s=30)
    assert not np.array_equal(a.x, b.x)
    assert a.messages != b.messages


def test_robot_seed_fixes_the_robot_not_the_run():
    a = simulate(seed=1, duration_s=20, robot_seed=4)
    b = simulate(seed=2, duration_s=20, robot_seed=4)
    c = simulate(seed=1, duration_s=20, robot_seed=5)
    plain = simulate(seed=1, duration_s=20)
    assert a.config["a_max"] == b.config["a_max"] != c.config["a_max"]
    assert a.config["robot_seed"] == 4 and "robot_seed" not in plain.config
    assert not np.array_equal(a.true_x, b.true_x)
    # one robot: same odometry calibration, so the same wheel travel reads the same twist
    still = simulate(seed=1, duration_s=20, robot_seed=5)
    assert np.array_equal(c.vx, still.vx)


def _yaw_mismatch(run, sel):
    """Largest |pose yaw change - integrated twist yaw| over 0.5 s inside `sel`, rad/s."""
    t = (run.stamp_ns - run.stamp_ns[0]) / 1e9
    step = np.diff(np.unwrap(run.yaw)) - 0.5 * (run.wz[1:] + run.wz[:-1]) * np.diff(t)
    c = np.concatenate(([0.0], np.cumsum(step)))
    k = int(round(0.5 * run.config["rate_hz"]))
    m = np.abs(c[k:] - c[:-k]) / 0.5  # m[j]: messages j .. j+k
    inside = np.array([sel[j:j + k + 1].all() for j in range(len(m))])
    return m[inside].max()


@pytest.mark.parametrize("heading", ["wheels", "imu"])
def test_wheel_slip_shows_as_yaw_mismatch_only_with_imu_heading(heading):
    run = simulate(seed=11, duration_s=45, anomalies=1, kinds=["wheel_slip"],
                   severity=(0.3, 0.3), robot_seed=3, heading=heading)
    (ev,) = run.events
    slip = _yaw_mismatch(run, _window(run, ev))
    calm = _yaw_mismatch(run, ~_window(run, ev, pad_s=0.6))
    assert calm < 0.05
    if heading == "imu":  # the gyro does not turn with the slipping wheel
        assert slip > 0.3 and run.config["heading"] == "imu"
    else:  # pose and twist come from the same wheel travel: they agree
        assert slip < 0.05 and "heading" not in run.config


# --- nominal runs --------------------------------------------------------------------

def test_nominal_run_has_no_events_and_stays_in_limits():
    run = simulate(seed=3, duration_s=300, rate_hz=100)
    assert run.events == [] and not run.anomalous.any()
    assert run.labels_dict()["events"] == []
    assert np.abs(run.true_v).max() <= 1.0 + 1e-6
    assert np.abs(run.true_w).max() <= 1.2 + 1e-6
    assert np.abs(_accel(run)).max() <= run.config["a_max"] * 1.05
    # it drives, stops and turns: not one pattern
    assert np.percentile(run.true_v, 90) > 0.4
    assert (np.abs(run.true_v) < 0.01).mean() > 0.02
    assert np.abs(run.true_w).max() > 0.5
    # reported twist follows the truth
    assert np.median(np.abs(run.vx - run.true_v)) < 0.02


def test_nominal_runs_differ_in_their_speed_profile():
    medians = {round(float(np.median(simulate(seed=s, duration_s=120).true_v)), 2) for s in range(4)}
    assert len(medians) >= 3


# --- anomalies show where the labels say -----------------------------------------------

def _disturbed(run, ev) -> bool:
    """Whether the arrays inside the event's window show its kind's disturbance."""
    w = _window(run, ev)
    dt = np.diff(run.stamp_ns) / 1e9
    a_max = run.config["a_max"]
    kind = ev.kind
    if kind == "acceleration":
        return np.abs(_accel(run)[w]).max() > 1.5 * a_max
    if kind == "twist":
        return np.abs(run.true_w[w]).max() > 1.5
    if kind == "spin":
        turned = np.sum(np.abs(run.true_w[1:][w[1:]]) * dt[w[1:]])
        return turned > np.pi and np.abs(run.true_v[w]).max() < 0.05 + np.abs(run.true_v[w][0])
    if kind == "back_and_forth":
        return run.true_v[w].min() < -0.1 and run.true_v[w].max() > 0.1
    if kind == "oscillation":
        s = np.sign(run.true_w[w][np.abs(run.true_w[w]) > 0.2])
        return np.count_nonzero(np.diff(s)) >= 3
    if kind == "stuck":
        late = w & (run.stamp_ns > ev.start_ns + int(2e9))
        return np.abs(run.true_v[late]).max() < 0.1 and (ev.end_ns - ev.start_ns) >= 6e9
    if kind == "collision":
        return run.true_v[w].min() < -0.05 and np.abs(_accel(run)[w]).max() > 3.0
    if kind == "wheel_slip":
        err = np.maximum(np.abs(run.vx - run.true_v), np.abs(run.wz - run.true_w))
        return err[w].max() > 0.2
    # localization: pose increments that the reported twist does not explain
    i = np.flatnonzero(w)
    i = i[i > 0]
    d = dt[i - 1]
    yaw_mid = run.yaw[i - 1] + 0.5 * run.wz[i] * d
    miss = np.hypot(run.x[i] - run.x[i - 1] - run.vx[i] * np.cos(yaw_mid) * d,
                    run.y[i] - run.y[i - 1] - run.vx[i] * np.sin(yaw_mid) * d)
    if kind == "pose_jump":
        return miss.max() > 0.1
    assert kind == "pose_twist_mismatch"
    return miss.sum() > 0.1


@pytest.mark.parametrize("kind", KINDS)
def test_each_kind_is_visible_inside_its_window_only(kind):
    run = simulate(seed=11, duration_s=45, rate_hz=100, anomalies=1, kinds=[kind], severity=(1, 1))
    (ev,) = run.events
    assert ev.kind == kind and ev.group == KIND_GROUPS[kind] and ev.severity == 1.0
    assert _disturbed(run, ev), f"{kind} window shows no disturbance"
    w = _window(run, ev)
    assert (run.labels[w] == KINDS.index(kind) + 1).all() and not run.labels[~w].any()
    # outside the window (with a second for the motor lag to settle) everything is nominal
    quiet = ~_window(run, ev, pad_s=1.0)
    assert np.abs(_accel(run)[quiet]).max() <= run.config["a_max"] * 1.05
    assert np.abs(run.true_w[quiet]).max() <= 1.2 + 1e-6
    assert np.abs(run.vx - run.true_v)[quiet].max() < 0.1


def test_mild_cases_are_milder():
    def peak(sev):
        run = simulate(seed=5, duration_s=30, anomalies=1, kinds=["twist"], severity=(sev, sev))
        return np.abs(run.true_w[run.anomalous]).max()

    assert peak(0.2) < peak(1.0) < peak(2.0)


def test_count_kinds_and_severity_range_are_honoured():
    run = simulate(seed=2, duration_s=400, anomalies=12, kinds=["collision", "spin"], severity=(0.3, 0.6))
    assert len(run.events) == 12
    assert {e.kind for e in run.events} == {"collision", "spin"}
    assert all(0.3 <= e.severity <= 0.6 for e in run.events)
    starts = [e.start_ns for e in run.events]
    assert starts == sorted(starts)
    assert all(a.end_ns < b.start_ns for a, b in zip(run.events, run.events[1:]))
    assert all(run.stamp_ns[0] <= e.start_ns < e.end_ns <= run.stamp_ns[-1] for e in run.events)


def test_rate_per_minute_gives_about_that_many():
    counts = [len(simulate(seed=s, duration_s=600, anomaly_rate_per_min=1.0).events) for s in range(3)]
    assert all(3 <= c <= 20 for c in counts)


# --- output: bag, JSON, JSONL, labels -------------------------------------------------

@pytest.mark.parametrize("rate", [10, 30, 100])
def test_bag_opens_with_right_count_and_rate(tmp_path, rate):
    run = simulate(seed=4, duration_s=20, rate_hz=rate, anomalies=1)
    run.write(tmp_path)
    with AnyReader([tmp_path / "run"]) as reader:
        (conn,) = reader.connections
        assert (conn.topic, conn.msgtype) == ("/odom", "nav_msgs/msg/Odometry")
        stamps = [t for _, t, _ in reader.messages()]
    assert len(stamps) == 20 * rate == len(run)
    period = np.diff(stamps) / 1e9
    assert (period > 0).all()
    assert np.median(period) == pytest.approx(1 / rate, rel=0.05)


def test_json_from_bag_equals_json_in_memory(tmp_path):
    run = simulate(seed=9, duration_s=20, rate_hz=30, anomalies=2)
    run.write(tmp_path, imu=True, tf=True)
    got: dict[str, list] = {}
    with AnyReader([tmp_path / "run"]) as reader:
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            got.setdefault(conn.topic, []).append((t, message_to_json(msg)))
            if conn.topic != "/tf":
                assert message_stamp_ns(msg) == t
    for topic in ("/odom", "/imu", "/tf"):
        assert got[topic] == run.topic_messages(topic), topic
    assert got["/odom"] == run.messages
    # the in-memory text is message_to_json of the very objects written
    assert [message_to_json(m) for m in run.ros_messages("/odom")] == [t for _, t in run.messages]

    lines = (tmp_path / "run.jsonl").read_text().splitlines()
    assert len(lines) == 3 * len(run)
    odom = [json.loads(line) for line in lines if '"topic": "/odom"' in line]
    assert [(o["stamp_ns"], json.dumps(o["msg"])) for o in odom] == run.messages

    labels = json.loads((tmp_path / "labels.json").read_text())
    assert [(e["start_ns"], e["end_ns"], e["kind"]) for e in labels["events"]] == [
        (e.start_ns, e.end_ns, e.kind) for e in run.events
    ]


@pytest.mark.parametrize("topic", ["/odom", "/imu", "/tf"])
def test_cdr_template_equals_rosbags_serializer(topic):
    from cclogfs.sim.messages import TYPESTORE
    from cclogfs.sim.run import _spec

    run = simulate(seed=6, duration_s=5, rate_hz=30, start_ns=(2**31 - 10) * 10**9)
    spec = _spec(topic)
    want = [bytes(TYPESTORE.serialize_cdr(m, spec.msgtype)) for m in run.ros_messages(topic)]
    assert spec.cdr(run._arrays(topic)) == want


def test_cli_writes_a_run(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["simulate", "--seed", "1", "--duration", "20", "--rate", "10",
                 "--anomalies", "1", "--severity", "0.5:0.7", "--out", str(out)]) == 0
    assert "200 /odom messages" in capsys.readouterr().out
    events = json.loads((out / "labels.json").read_text())["events"]
    assert len(events) == 1 and 0.5 <= events[0]["severity"] <= 0.7
    assert main(["simulate", "--nominal", "--duration", "20", "--robot-seed", "3",
                 "--heading", "imu", "--out", str(tmp_path / "n")]) == 0
    labels = json.loads((tmp_path / "n" / "labels.json").read_text())
    assert labels["events"] == []
    assert labels["run"]["robot_seed"] == 3 and labels["run"]["heading"] == "imu"
    # a second write into the same place is refused, not merged
    assert main(["simulate", "--nominal", "--duration", "20", "--out", str(out)]) == 1
    assert "exists already" in capsys.readouterr().err


# --- bad arguments --------------------------------------------------------------------

@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(duration_s=0), "duration_s"),
        (dict(duration_s=float("nan")), "duration_s"),
        (dict(rate_hz=0.5), "rate_hz"),
        (dict(rate_hz=5000), "rate_hz"),
        (dict(seed=-1), "seed"),
        (dict(seed=1.5), "seed"),
        (dict(anomalies=-2), "anomalies"),
        (dict(severity=(1.5, 0.5)), "severity"),
        (dict(severity=(0, 1)), "severity"),
        (dict(kinds=["teleport"]), "unknown anomaly kind"),
        (dict(kinds="spin"), "kinds"),
        (dict(start_ns=-1), "start_ns"),
        (dict(start_ns=(2**31 - 5) * 10**9, duration_s=10), "start_ns"),
        (dict(duration_s=20, anomalies=10), "do not fit|longer duration"),
        (dict(robot_seed=-1), "robot_seed"),
        (dict(heading="compass"), "heading"),
    ],
)
def test_bad_arguments_are_clear_errors(kwargs, match):
    with pytest.raises(InvalidInputError, match=match):
        simulate(**kwargs)


def test_unknown_topic_is_a_clear_error():
    with pytest.raises(InvalidInputError, match="not simulated"):
        simulate(duration_s=5).topic_messages("/scan")
