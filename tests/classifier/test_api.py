import numpy as np
import pytest

from cclogfs.classifier import (Detector, OneClassModel, SmartLogger, collect, event_table,
                                format_event_table, format_message_table, load_dataset,
                                message_table, train, window_spans)
from cclogfs.classifier.api import HOLD_SCORE
from cclogfs.classifier.features import NS
from cclogfs.classifier.testing import inject, odom_texts
from cclogfs.errors import InvalidInputError, ModelError


@pytest.fixture(scope="module")
def quiet(halves):
    """The test half without nav2's spin (first 8 s) and back-up (44-46 s) recoveries."""
    s = (halves[1].stamp_ns - halves[1].stamp_ns[0]) / NS
    return halves[1].take((s > 16) & (s < 43))


@pytest.fixture(scope="module")
def model(halves):
    return train([halves[0]])


def test_live_scores_equal_batch_scores(model, halves):
    test = halves[1]
    scores, flags = Detector(model).score_batch(test)
    live = Detector(model)
    got = np.array([live.update(text)[0] for text in odom_texts(test)])
    np.testing.assert_allclose(got, scores, atol=1e-9, equal_nan=True)


def test_injected_anomalies_found_and_clean_run_quiet(model, halves, quiet):
    _, flags = Detector(model).score_batch(halves[1])
    # nav2 spins in place (first 8 s) and backs up (44-46 s) in this half only: its spin and
    # back-up recoveries, which the default features flag like the simulator's spin and
    # back-and-forth anomalies. Between them the robot drives as in the training half.
    s = (halves[1].stamp_ns - halves[1].stamp_ns[0]) / NS
    assert flags[(s > 16) & (s < 43)].sum() == 0 and flags[s > 43].any()
    test = quiet
    start = int(test.stamp_ns[np.argmax(np.hypot(test.raw[:, 7], test.raw[:, 8]) > 0.3)]) + 5 * NS
    for kind in ("accel", "pose_jump", "stop", "twist"):
        run, event = inject(test, kind, start, 0.4)
        scores, flags = Detector(model).score_batch(run)
        table = message_table(run.stamp_ns, flags, {"events": [event]})
        assert table["tp"] > 0, kind
        assert flags[run.stamp_ns < event["start_ns"]].sum() == 0, kind


def test_smart_logger_live_equals_replay_and_windows_cover_event(model, quiet):
    run, event = inject(quiet, "spin", int(quiet.stamp_ns[300]), 4.0)
    stream = [("/odom", int(s), x) for s, x in zip(run.stamp_ns, odom_texts(run))]
    stream.insert(5, ("/tf_static", int(run.stamp_ns[5]), '{"transforms": []}'))
    live = list(SmartLogger(Detector(model), before_s=4, after_s=4).run(stream))
    batch = SmartLogger(Detector(model), before_s=4, after_s=4).replay(stream)
    assert [(w.topic, w.messages, w.meta) for w in live] == [(w.topic, w.messages, w.meta) for w in batch]
    stream[7:7] = [("/imu", int(run.stamp_ns[i]), f'{{"i": {i}}}') for i in range(7, 400)]
    one = list(SmartLogger(Detector(model), before_s=4, after_s=4).run(stream))
    held = list(SmartLogger(Detector(model), before_s=4, after_s=4, batch=7).run(stream))
    assert [(w.topic, w.messages, w.meta) for w in held] == [(w.topic, w.messages, w.meta) for w in one]
    assert any(w.topic == "/imu" for w in held)
    spans = window_spans(live)
    table = event_table(run.stamp_ns, spans, {"events": [event]})
    assert table["recalled"] == 1 and table["false_windows"] == 0
    assert 0 < table["kept_fraction"] < 0.7  # a 27 s run: 4 s spin, 4 s context each side
    assert {w.topic for w in live} == {"/odom", "/tf_static", "/cclog/summary"}
    assert "Events recalled" in format_event_table(table)


def test_quiet_batches_skip_the_svm_with_the_same_windows(model, quiet):
    """A held batch whose limits bound every score below the hold level is not scored by
    the SVM (SmartLogger._scores); the windows are the same as with every batch scored."""
    run, event = inject(quiet, "spin", int(quiet.stamp_ns[300]), 4.0)
    stream = [("/odom", int(s), x) for s, x in zip(run.stamp_ns, odom_texts(run))]
    stream[7:7] = [("/imu", int(run.stamp_ns[i]), f'{{"i": {i}}}') for i in range(7, 400)]
    skipping = SmartLogger(Detector(model), before_s=2, after_s=1, batch=64)
    scoring = SmartLogger(Detector(model), before_s=2, after_s=1, batch=64)
    scoring._quiet_below = -np.inf  # every batch through the SVM, as before
    svm_calls = []
    model_score = model.score
    model.score = lambda X, *limits: svm_calls.append(len(X)) or model_score(X, *limits)
    try:
        got = list(skipping.run(stream))
        skipped = len(svm_calls)
        want = list(scoring.run(stream))
    finally:
        del model.score
    assert [(w.topic, w.messages, w.meta) for w in got] == [(w.topic, w.messages, w.meta) for w in want]
    assert any(w.meta.get("n_triggers") for w in got)  # the spin opened a window
    assert 0 < skipped < len(svm_calls) - skipped  # some batches scored, fewer than all
    X, valid = Detector(model).features.batch(run)
    X = X[valid]
    limits = skipping.detector.limits.copy()  # as the run left them (grown live)
    for at in range(0, len(X), 64):  # a batch: its exact scores, or none could matter
        skipping.detector.limits = limits.copy()
        full, got = model.score(X[at : at + 64], limits.copy()), skipping._scores(X[at : at + 64])
        assert got.tobytes() == full.tobytes() or (got.max() <= HOLD_SCORE and full.max() <= HOLD_SCORE)


def test_paper_table_layout():
    stamps = np.arange(10) * NS
    flags = np.array([0, 1, 1, 0, 0, 0, 1, 0, 0, 0], bool)
    t = message_table(stamps, flags, {"events": [{"start_ns": 1 * NS, "end_ns": 3 * NS, "kind": "x"}]})
    assert (t["tp"], t["fp"], t["fn"], t["tn"]) == (2, 1, 1, 6)
    assert "Precision           66.7%" in format_message_table(t)
    with pytest.raises(InvalidInputError, match="Labels"):
        message_table(stamps, flags, {"events": [{"start": 1}]})


def test_model_roundtrip_and_feature_mismatch(model, tmp_path):
    path = model.save(tmp_path / "m")
    back = OneClassModel.load(path, feature_config=model.feature_config)
    assert Detector(back).model.model_id_ == model.model_id_
    back.feature_config = {"id": "paper", "version": 1, "params": {"window": 500, "stride": 2}}
    with pytest.raises(ModelError, match="expects 11 features"):
        Detector(back)


def test_collect_dataset(halves, tmp_path):
    run, event = inject(halves[1], "accel", int(halves[1].stamp_ns[400]), 0.4)
    meta = collect(run, tmp_path / "ds", labels={"events": [event]})
    config, nominal, anomalous = load_dataset(tmp_path / "ds")
    assert config["id"] == "default" and len(nominal) == meta["nominal"] > 500
    assert len(anomalous) == meta["anomalous"] > 0
    with pytest.raises(InvalidInputError, match="other features"):
        collect(run, tmp_path / "ds", features={"id": "paper", "params": {"window": 10, "stride": 1}})
