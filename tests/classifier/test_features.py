import json

import numpy as np
import pytest

from cclogfs.classifier.features import (NS, OdomArrays, make_features, odom_row,
                                         parse_odometry)
from cclogfs.classifier.testing import odom_texts, read_odometry, resample
from cclogfs.errors import InvalidInputError


def synthetic(n=600, rate=20.0, seed=0):
    """A robot driving a wavy path, with stamp jitter, one gap and one repeated stamp."""
    rng = np.random.default_rng(seed)
    t = (np.arange(n) / rate * NS).astype(np.int64) + rng.integers(-2_000_000, 2_000_000, n)
    t[300:] += 3 * NS  # a gap: features restart
    if n > 100:
        t[100] = t[99]  # a repeated stamp: not advancing
    s = (t - t[0]) * 1e-9
    yaw = 0.5 * np.sin(0.3 * s)
    raw = np.zeros((n, 13))
    raw[:, 0], raw[:, 1] = np.cumsum(0.4 * np.cos(yaw)) / rate, np.cumsum(0.4 * np.sin(yaw)) / rate
    raw[:, 5], raw[:, 6] = np.sin(yaw / 2), np.cos(yaw / 2)
    raw[:, 7] = 0.4 + 0.05 * rng.standard_normal(n)
    raw[:, 12] = 0.15 * np.cos(0.3 * s) + 0.02 * rng.standard_normal(n)
    if n > 200:
        raw[200, 7] = np.nan  # a broken message: repeats the previous vector
    return OdomArrays(t, raw)


@pytest.mark.parametrize("fid", ["default", "paper"])
def test_batch_equals_incremental(fid):
    feature_set = make_features({"id": fid, "params": {"window": 40, "stride": 2}} if fid == "paper" else fid)
    odom = synthetic()
    X, valid = feature_set.batch(odom)
    stream = feature_set.stream()
    for i, (stamp, row) in enumerate(zip(odom.stamp_ns.tolist(), odom.raw)):
        got = stream.push(stamp, row)
        if got is None:
            assert not valid[i]
            continue
        vec, ok = got
        assert ok == valid[i], i
        if ok:
            np.testing.assert_allclose(vec, X[i], rtol=1e-9, atol=1e-9)
    assert valid.sum() > 400


def test_default_features_restart_after_gap_and_hold_on_bad_messages():
    feature_set = make_features("default")
    odom = synthetic()
    X, valid = feature_set.batch(odom)
    assert not valid[300:315].any()  # 1 s warm-up after the 3 s gap (20 Hz)
    assert valid[330]
    np.testing.assert_array_equal(X[200], X[199])  # NaN message repeats the vector
    np.testing.assert_array_equal(X[100], X[99])  # repeated stamp too


def test_default_features_invariant_to_position_and_heading():
    odom = synthetic()
    feature_set = make_features("default")
    X, valid = feature_set.batch(odom)
    moved = odom.raw.copy()
    a = 2.0  # rotate the world by 2 rad and shift it
    c, s = np.cos(a), np.sin(a)
    moved[:, 0], moved[:, 1] = c * odom.raw[:, 0] - s * odom.raw[:, 1] + 50, s * odom.raw[:, 0] + c * odom.raw[:, 1] - 7
    yaw = 2 * np.arctan2(odom.raw[:, 5], odom.raw[:, 6]) + a
    moved[:, 5], moved[:, 6] = np.sin(yaw / 2), np.cos(yaw / 2)
    X2, _ = feature_set.batch(OdomArrays(odom.stamp_ns, moved))
    np.testing.assert_allclose(X2[valid], X[valid], atol=1e-6)


def test_default_features_similar_across_rates(shared_data):
    odom = parse_odometry(read_odometry(shared_data("nav2_turtlebot.mcap")))
    feature_set = make_features("default")
    med = []
    for rate in (10, 100):
        X, valid = feature_set.batch(resample(odom, rate, jitter_s=0.1 / rate))
        med.append(np.median(X[valid], axis=0))
    # turning in place is an integral: the same at any rate
    np.testing.assert_allclose(med[0][8], med[1][8], rtol=0.05, atol=0.01)


def test_paper_features_have_paper_size():
    feature_set = make_features("paper")
    assert feature_set.dim == 3250
    odom = synthetic(n=520)
    X, valid = feature_set.batch(odom)
    assert valid.sum() == 520 - 498
    np.testing.assert_array_equal(X[-1][-13:], odom.raw[-1])  # newest message last


def test_parse_dicts_and_texts_alike():
    odom = synthetic(n=250)
    texts = odom_texts(odom)
    a = parse_odometry(texts)
    b = parse_odometry(json.loads(x) for x in texts)
    np.testing.assert_array_equal(a.stamp_ns, odom.stamp_ns)
    np.testing.assert_array_equal(a.raw, b.raw)
    np.testing.assert_array_equal(np.isnan(a.raw), np.isnan(odom.raw))


def test_odom_text_fast_path_equals_json():
    from cclogfs.classifier.features import _ODOM_TEXT, odom_row

    msg = json.loads(odom_texts(synthetic(n=1))[0])
    msg["header"] = {"seq": 7, "stamp": {"sec": 12, "nanosec": 345}, "frame_id": 'od\\"o]m'}
    msg["child_frame_id"] = "base]"
    msg["pose"]["pose"]["position"] = {"x": -1.5e-07, "y": float("nan"), "z": float("-inf")}
    msg["twist"]["twist"]["angular"]["z"] = 12345678901234567890.0
    for text in (json.dumps(msg), json.dumps(msg, indent=1)):  # fast path, then json.loads
        got, want = odom_row(text), odom_row(msg)
        assert got[0] == want[0] == 12 * NS + 345
        np.testing.assert_array_equal(got[1], want[1])
    assert _ODOM_TEXT.fullmatch(json.dumps(msg)) and not _ODOM_TEXT.fullmatch(json.dumps(msg, indent=1))


def test_bad_message_and_config_errors():
    # A pose without twist is a PoseWithCovarianceStamped now (issue 12); without orientation it is nothing.
    with pytest.raises(InvalidInputError, match="message 2: .*orientation"):
        parse_odometry([odom_texts(synthetic(n=1))[0], '{"header": {"stamp": {"sec": 1, "nanosec": 0}}, "pose": {"pose": {"position": {"x":0,"y":0,"z":0}}}}'])
    with pytest.raises(InvalidInputError):
        odom_row("not json")
    with pytest.raises(InvalidInputError, match="Unknown feature set"):
        make_features("nope")
    with pytest.raises(InvalidInputError, match="version"):
        make_features({"id": "default", "version": 99})
