"""The window policy a list at a time (issue 14): `WindowBuilder.push_run` and
`SmartLogger.push_many` give the windows `push` gives a message at a time, in the same order."""

from itertools import groupby

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.classifier import Detector, SmartLogger, parse_odometry, train
from cclogfs.classifier.features import NS
from cclogfs.classifier.testing import inject, odom_texts, read_odometry
from cclogfs.classifier.windows import WindowBuilder

MS = 1_000_000


def as_tuples(windows):
    return [(w.topic, w.messages, w.meta) for w in windows]


# A message: (topic, stamp step in ms, score). Steps below 0 go back (-1500: a clock
# reset), scores above -0.3 hold an open window, above 0 are anomalous.
message = st.tuples(st.sampled_from(["/odom"] * 6 + ["/imu", "/tf_static"]),
                    st.sampled_from([100, 100, 100, 0, 40, 900, 5000, -30, -1500]),
                    st.sampled_from([-1.0] * 12 + [-0.2, 0.5]))  # fmt: skip


def stream_of(steps):
    """(topic, stamp, text, anomalous, score) of each drawn message."""
    out, t = [], 10 * NS
    for k, (topic, step, score) in enumerate(steps):
        t += step * MS
        out.append((topic, t, f'{{"k": {k}}}', topic == "/odom" and score > 0, score))
    return out


@pytest.mark.parametrize("mode", [
    {"before_s": 2, "after_s": 1, "lookback_max_s": 1, "merge_s": 3, "hold_score": -0.3, "max_ring": 30},
    {"before_s": 0.3, "after_s": 0.2, "lookback_max_s": 0.2, "merge_s": 0.3, "hold_score": -0.3, "max_ring": 6},
    {"before_s": 0.5, "after_s": 0},
    {"before": 3, "after": 2},
])  # fmt: skip
@settings(max_examples=150, deadline=None)
@given(steps=st.lists(message, max_size=120), cut_at=st.integers(0, 120))
def test_push_run_is_push_of_each(mode, steps, cut_at):
    check_push_run(mode, steps, cut_at)


def check_push_run(mode, steps, cut_at):
    """Messages a run at a time give `push`'s windows, ring and pending queues; a `cut`
    before message `cut_at` too."""
    stream = stream_of(steps)
    one, runs = WindowBuilder(max_part=7, **mode), WindowBuilder(max_part=7, **mode)
    want = []
    for k, (topic, t, text, anomalous, score) in enumerate(stream):
        if k == cut_at:
            want += one.cut()
        want += one.push(topic, t, text, anomalous=anomalous, score=score, lookback_ns=400 * MS)
    got, k = [], 0
    for is_odom, group in groupby(stream, key=lambda m: m[0] == "/odom"):
        group = list(group)
        if is_odom:
            if k <= cut_at < k + len(group):  # cut where the message-at-a-time side cut
                at = cut_at - k
                got += _run(runs, group[:at]) + runs.cut()
                got += _run(runs, group[at:])
            else:
                got += _run(runs, group)
        else:
            for j, (topic, t, text, anomalous, score) in enumerate(group):
                if k + j == cut_at:
                    got += runs.cut()
                got += runs.push(topic, t, text)
        k += len(group)
    assert as_tuples(got) == as_tuples(want)
    assert list(runs.ring) == list(one.ring) and runs.pending == one.pending
    assert as_tuples(runs.flush()) == as_tuples(one.flush())


jitter = st.tuples(st.sampled_from(["/odom"] * 5 + ["/imu"]), st.integers(-200, 150), st.just(-1.0))


@settings(max_examples=300, deadline=None)
@given(steps=st.lists(jitter, max_size=30))
def test_push_run_with_stamps_going_back(steps):
    """Stamps that jitter back leave the ring out of order: trimming it once for many
    messages would then keep other messages than trimming it after each."""
    check_push_run({"before_s": 0.3, "after_s": 0.2, "lookback_max_s": 0.2, "max_ring": 4}, steps, len(steps))


def _run(builder, group):
    if not group:
        return []
    _, stamps, texts, anomalous, scores = map(list, zip(*group))
    return builder.push_run(stamps, texts, anomalous, scores, [400 * MS] * len(group))


@pytest.fixture(scope="module")
def odom():
    from conftest import shared_data_file

    odom = parse_odometry(read_odometry(shared_data_file("nav2_turtlebot.mcap")))
    t = odom.stamp_ns
    return odom.take(t < t[0] + (t[-1] - t[0]) // 2), odom.take(t >= t[0] + (t[-1] - t[0]) // 2)


@pytest.mark.parametrize("size", [1, 5, 64, 300, 1000])
@pytest.mark.parametrize("others", [False, True])
def test_smart_logger_push_many_is_push_of_each(odom, size, others):
    """Real odometry with a spin and a stop injected, a stamp that goes back and a clock
    reset, per-10-second summaries; with `others`, IMU messages and a latched topic too."""
    model = train([odom[0]])
    run, _ = inject(odom[1], "spin", int(odom[1].stamp_ns[300]), 4.0)
    run, _ = inject(run, "stop", int(run.stamp_ns[900]), 0.5)
    stream = [("/odom", int(s), x) for s, x in zip(run.stamp_ns, odom_texts(run))]
    stream[700] = ("/odom", stream[699][1] - 5 * MS, stream[700][2])  # jitter back
    stream[1100:] = [("/odom", s - 30 * NS, x) for _, s, x in stream[1100:]]  # a clock reset
    if others:
        stream[7:7] = [("/imu", s + 1, f'{{"i": {i}}}') for i, (_, s, _) in enumerate(stream[7:600])]
        stream.insert(5, ("/tf_static", stream[5][1], '{"transforms": []}'))
    one = SmartLogger(Detector(model), before_s=2, after_s=1, batch=64, summary_period_s=10)
    many = SmartLogger(Detector(model), before_s=2, after_s=1, batch=64, summary_period_s=10)
    want = [w for m in stream for w in one.push(*m)] + one.flush()
    got = [w for i in range(0, len(stream), size) for w in many.push_many(stream[i : i + size])] + many.flush()
    assert as_tuples(got) == as_tuples(want)
    assert any(w.meta.get("n_triggers") for w in got) and any(w.topic == "/cclog/summary" for w in got)
    assert (many.scored, many.anomalies) == (one.scored, one.anomalies)


def test_push_many_stops_at_a_bad_odometry_message(odom):
    """The messages before a bad one are held (and flushed) as `push` holds them."""
    model = train([odom[0]])
    stream = [("/odom", int(s), x) for s, x in zip(odom[1].stamp_ns[:100], odom_texts(odom[1].take(slice(0, 100))))]
    stream[70] = ("/odom", stream[70][1], '{"not": "odometry"}')
    one = SmartLogger(Detector(model), before_s=2, after_s=1, batch=64)
    many = SmartLogger(Detector(model), before_s=2, after_s=1, batch=64)
    with pytest.raises(Exception) as want:
        for m in stream:
            one.push(*m)
    with pytest.raises(type(want.value), match="missing or bad field"):
        many.push_many(stream)
    assert len(many._pending) == len(one._pending) == 70 - 64
    assert as_tuples(many.flush()) == as_tuples(one.flush())


def test_push_many_of_nothing(odom):
    logger = SmartLogger(Detector(train([odom[0]])), before_s=2, after_s=1, batch=64)
    assert logger.push_many([]) == [] and logger.flush() == []
