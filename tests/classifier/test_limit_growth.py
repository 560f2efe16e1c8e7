"""Issue 15, fourth pass: the second stage's limits grow online from what the robot shows
while the SVM judges it nominal; never from what the SVM flags."""

import json

import numpy as np
import pytest
from test_long_runs import manoeuvres

from cclogfs.classifier import Detector, train
from cclogfs.classifier.features import NS, make_features
from cclogfs.classifier.model import OneClassModel
from cclogfs.errors import ModelError


def _models():
    odom = manoeuvres()
    part = odom.take(odom.stamp_ns < odom.stamp_ns[0] + 19 * NS)
    return odom, train([part]), train([part], limit_growth=0), train([part], limit_factor=0)


def test_limits_grow_only_from_vectors_the_svm_calls_nominal():
    odom, grown, fixed, svm_only = _models()
    assert grown.limit_growth_ == 1.0 and fixed.limit_growth_ == 0.0 and grown.model_id_ != fixed.model_id_
    X, ok = make_features(grown.feature_config).batch(odom)
    X = X[ok]
    svm = svm_only.score(X)
    limits = grown.limits_.copy()
    got = grown.score(X, limits)
    # The rule, row by row: a row's limits are at least the largest values of the rows
    # before it that the SVM called nominal.
    seen, want = np.zeros(X.shape[1]), []
    for x, s in zip(X, svm):
        want.append(min(s, float(np.max(x / np.maximum(grown.limits_, seen))) - 1.0))
        if s <= 0:
            seen = np.maximum(seen, x)
    np.testing.assert_allclose(got, want, atol=1e-12)
    np.testing.assert_array_equal(limits, np.maximum(grown.limits_, seen))
    # Growth only takes flags away, and here it does take some; without the limits to
    # grow, the rows are scored independently, as with fixed limits.
    flagged_fixed = fixed.score(X) > 0
    assert not ((got > 0) & ~flagged_fixed).any() and ((got <= 0) & flagged_fixed).any()
    np.testing.assert_allclose(grown.score(X), fixed.score(X), atol=1e-12)


def test_live_batch_and_chunked_scores_agree():
    odom, grown, _, _ = _models()
    batch, _ = Detector(grown).score_batch(odom)
    live = Detector(grown)
    one = np.array([live.update_row(int(t), tuple(r))[0] for t, r in zip(odom.stamp_ns, odom.raw.tolist())])
    ok = np.isfinite(batch)
    np.testing.assert_allclose(one[ok], batch[ok], atol=1e-9)
    X, valid = make_features(grown.feature_config).batch(odom)
    limits = grown.limits_.copy()
    chunks = np.concatenate([grown.score(c, limits) for c in np.array_split(X[valid], 7)])
    np.testing.assert_allclose(chunks, batch[valid], atol=1e-12)
    np.testing.assert_array_equal(limits, live.limits)
    assert (limits > grown.limits_).any()


def test_growth_saved_and_old_or_bad_files(tmp_path):
    _, grown, fixed, _ = _models()
    back = OneClassModel.load(grown.save(tmp_path / "g"))
    assert back.limit_growth_ == 1.0 and back.model_id_ == grown.model_id_
    path = fixed.save(tmp_path / "f")
    assert "limit_growth" not in json.loads((path / "model.json").read_text())  # as files before it
    assert OneClassModel.load(path).limit_growth_ == 0.0
    header = json.loads((tmp_path / "g" / "model.json").read_text())
    for bad in (-1.0, "x"):
        (tmp_path / "g" / "model.json").write_text(json.dumps(header | {"limit_growth": bad}))
        with pytest.raises(ModelError, match="limit_growth"):
            OneClassModel.load(tmp_path / "g")
    with pytest.raises(ModelError, match="growth"):
        fixed.set_limits(fixed.limits_, -0.5)


def test_stages_apart_give_the_score():
    """`svm_score` and `row_limits` (the two stages apart, for bench/classifier_long.py
    --misses) give `score` back: the smaller of the SVM's score and the largest feature
    over the limits each row was judged by, grown row by row as scoring grows them."""
    odom, grown, _, svm_only = _models()
    X, ok = make_features(grown.feature_config).batch(odom)
    X = X[ok]
    svm = grown.svm_score(X)
    np.testing.assert_allclose(svm, svm_only.score(X), atol=1e-12)  # the same SVM, no limits
    rows = grown.row_limits(X, svm, grown.limits_.copy())
    assert rows.shape == X.shape and (rows[0] == grown.limits_).all() and (np.diff(rows, axis=0) >= 0).all()
    both = np.minimum(svm, np.max(X / rows, axis=1) - 1.0)
    np.testing.assert_allclose(both, grown.score(X, grown.limits_.copy()), atol=1e-12)
    assert grown.row_limits(X, svm) is grown.limits_  # no limits to grow: the trained ones
