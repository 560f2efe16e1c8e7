"""The compiled live feature stream (cclogfs/classifier/_stream.c) gives the Python
stream's (vector, valid) bit for bit, message after message, for every feature version."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cclogfs.classifier import features
from cclogfs.classifier.features import _CompiledDefaultStream, _DefaultStream, make_features, parse_odometry
from cclogfs.classifier.testing import inject, read_odometry

pytestmark = pytest.mark.skipif(features._Stream is None, reason="cclogfs.classifier._stream is not built")

CONFIGS = [
    "default",
    {"id": "default", "version": 6, "params": {"dir_flip": 0.07, "long_s": 3.0, "gap_s": 0.3}},
    {"id": "default", "version": 5, "params": {"gate_s": 1.0, "despike_s": 0.1}},
    {"id": "default", "version": 4, "params": {"gate_s": 0.5, "despike_s": 0.05}},
    {"id": "default", "version": 3},
]


def same_stream(config, rows):
    """Push (stamp, row) pairs through both streams; every answer bit for bit the same."""
    feature_set = make_features(config)
    python, compiled = _DefaultStream(feature_set), _CompiledDefaultStream(feature_set)
    answers = 0
    for stamp, row in rows:
        want, got = python.push(stamp, row), compiled.push(stamp, row)
        assert (want is None) == (got is None)
        if want is not None:
            assert want[1] == got[1] and want[0].tobytes() == got[0].tobytes(), (stamp, row)
            answers += 1
    return answers


def run_rows(odom):
    return list(zip(odom.stamp_ns.tolist(), odom.raw.tolist()))


@pytest.mark.parametrize("config", CONFIGS)
def test_real_runs_with_injected_anomalies(shared_data, config):
    odom = parse_odometry(read_odometry(shared_data("nav2_turtlebot.mcap")))
    rows = run_rows(odom)
    for kind in ("spin", "stop", "pose_jump", "twist"):
        run, _ = inject(odom, kind, int(odom.stamp_ns[len(odom) // 3]), 3.0)
        rows += [(s + 10**12, r) for s, r in run_rows(run)]  # after a gap: a restart too
    assert same_stream(config, rows) > len(rows) // 2


def test_long_real_run(shared_data):
    odom = parse_odometry(read_odometry(shared_data("long/tuc_corridor.mcap")))
    assert same_stream("default", run_rows(odom)) > 10_000


values = st.floats(-3, 3) | st.sampled_from([0.0, -0.0, 0, 1, math.nan, math.inf, 1e-300])
steps = st.integers(-2 * 10**7, 3 * 10**8)  # stamps going back, repeating, jumping past the gap


# 13 values a row make rows slow to draw on a loaded host: the health check would fail the run.
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(steps, st.lists(values, min_size=13, max_size=13)), min_size=1, max_size=40),
       st.sampled_from(CONFIGS))  # fmt: skip
def test_odd_rows_and_stamps(steps_rows, config):
    """Non-finite values, int values (JSON 0, whose negation is not -0.0), stamps that do
    not advance or leave a gap: the same answers, skipped messages included."""
    t, rows = 10**18, []
    for step, row in steps_rows:
        t += step
        rows.append((t, row))
    same_stream(config, rows)


def test_rows_of_any_sequence_type():
    feature_set = make_features("default")
    rows = [(10**9 + k * 10**7, [0.01 * k, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.1]) for k in range(300)]
    python, compiled = _DefaultStream(feature_set), _CompiledDefaultStream(feature_set)
    for stamp, row in rows:
        want = python.push(stamp, np.array(row))
        got = compiled.push(stamp, tuple(row))
    assert want[0].tobytes() == got[0].tobytes() and want[1] and got[1]
    with pytest.raises(ValueError):
        compiled.push(5 * 10**9, [0.0] * 12)
