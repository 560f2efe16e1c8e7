import json
import subprocess
import sys

import numpy as np
import pytest
from sklearn.svm import OneClassSVM

from cclogfs.classifier.model import OneClassModel
from cclogfs.errors import ModelError

CONFIG = {"id": "default", "version": 1, "params": {"x": 1.0}}


def nominal(n=1500, d=6, seed=0):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((n, d)) * [1, 2, 0.5, 1, 1, 3] + [0, 1, 2, 3, 4, 5]


@pytest.mark.parametrize("one_sided", [False, True])
def test_numpy_inference_matches_sklearn(one_sided):
    X = nominal()
    m = OneClassModel(feature_config=CONFIG, nu=0.05, gamma=0.2, one_sided=one_sided).fit(X)
    train, _ = m.split(X)
    ref = OneClassSVM(kernel="rbf", nu=m.nu_, gamma=m.gamma_).fit(m.transform(train))
    Q = nominal(300, seed=1) * 1.5
    np.testing.assert_allclose(m.decision_function(Q), ref.decision_function(m.transform(Q)), atol=1e-9)


def test_matches_sklearn_exactly_on_support_vectors():
    X = nominal()
    m = OneClassModel(feature_config=CONFIG, nu=0.05, gamma=0.2).fit(X)
    # The decision function only depends on SVs, coefficients, gamma and intercept.
    Z = m.transform(nominal(200, seed=2))
    k = np.exp(-m.gamma_ * ((Z[:, None, :] - m.support_vectors_[None]) ** 2).sum(-1))
    np.testing.assert_allclose(m.decision_function(nominal(200, seed=2)), k @ m.dual_coef_ + m.intercept_, atol=1e-9)


def test_threshold_flags_outliers_and_few_nominal():
    X = nominal()
    m = OneClassModel(feature_config=CONFIG).fit(X)
    assert m.predict(nominal(2000, seed=3)).mean() < 0.01
    far = nominal(50, seed=4) + 8.0
    assert m.predict(far).all()


def test_labelled_anomalies_select_hyperparameters():
    X = nominal()
    anomalies = nominal(40, seed=5) + [3, 0, 0, 0, 0, 0]
    m = OneClassModel(feature_config=CONFIG, nu_grid=(0.01, 0.05), gamma_grid=(0.1, 1.0)).fit(X, anomalies)
    assert m.nu_ in (0.01, 0.05) and round(m.gamma_ * 6, 9) in (0.1, 1.0)
    assert m.validation_recall_ == pytest.approx(m.predict(anomalies).mean())


def test_save_load_roundtrip_without_pickle(tmp_path):
    m = OneClassModel(feature_config=CONFIG).fit(nominal())
    m.save(tmp_path / "m")
    header = json.loads((tmp_path / "m" / "model.json").read_text())
    assert header["format"] == "cclogfs-ocsvm" and header["model_id"] == m.model_id_
    back = OneClassModel.load(tmp_path / "m", feature_config=CONFIG)
    Q = nominal(100, seed=6)
    np.testing.assert_array_equal(back.score(Q), m.score(Q))
    with np.load(tmp_path / "m" / "model.npz", allow_pickle=False) as z:
        assert set(z.files) == {"mean", "scale", "support_vectors", "dual_coef", "intercept"}


def test_load_rejects_other_features_versions_and_damage(tmp_path):
    path = OneClassModel(feature_config=CONFIG).fit(nominal()).save(tmp_path / "m")
    with pytest.raises(ModelError, match="trained on features"):
        OneClassModel.load(path, feature_config={"id": "paper", "version": 1, "params": {}})
    header = json.loads((path / "model.json").read_text())
    (path / "model.json").write_text(json.dumps(header | {"format_version": 2}))
    with pytest.raises(ModelError, match="format_version 2"):
        OneClassModel.load(path)
    (path / "model.json").write_text(json.dumps(header))
    blob = bytearray((path / "model.npz").read_bytes())
    blob[-100] ^= 1
    (path / "model.npz").write_bytes(bytes(blob))
    with pytest.raises(ModelError, match="npz_sha256"):
        OneClassModel.load(path)
    with pytest.raises(ModelError, match="Cannot read"):
        OneClassModel.load(tmp_path / "missing")


@pytest.mark.parametrize("field, value", [("threshold", None), ("gamma", None), ("nu", None),
                                          ("feature_config", {**CONFIG, "params": {"x": 1.5}}),
                                          ("model_id", "0123456789abcdef")])  # fmt: skip
def test_load_rejects_a_model_json_changed_in_what_the_model_computes(tmp_path, field, value):
    """Found by attack: model.json has no checksum of its own (model.npz's is in it), so a
    flipped digit of the threshold, gamma or a feature parameter loaded without a word and
    smart logging kept other windows, exit 0, each stamped with the model id the file
    claimed. The model id covers those fields: a load computes it again and compares."""
    path = OneClassModel(feature_config=CONFIG).fit(nominal()).save(tmp_path / "m")
    header = json.loads((path / "model.json").read_text())
    header[field] = value if value is not None else header[field] * 1.0001
    (path / "model.json").write_text(json.dumps(header, indent=1))
    with pytest.raises(ModelError, match=r"model\.json.*model_id"):
        OneClassModel.load(path)


def test_load_accepts_what_the_model_id_leaves_out(tmp_path):
    """The training statistics and versions are not part of the model: editing them is no damage."""
    path = OneClassModel(feature_config=CONFIG).fit(nominal()).save(tmp_path / "m")
    header = json.loads((path / "model.json").read_text())
    header["training"], header["versions"] = {"rate_hz": 1.0}, {"cclogfs": "0.0.1"}
    (path / "model.json").write_text(json.dumps(header, indent=1))
    assert OneClassModel.load(path).model_id_ == header["model_id"]


def test_load_imports_no_scikit_learn(tmp_path):
    """Scoring is numpy alone; loading a model checks its id without the library versions,
    so `record --model` imports no scikit-learn (the check once imported it for the
    versions it then left out: ~2 s of CPU and ~75 MiB more for every smart recording)."""
    path = OneClassModel(feature_config=CONFIG).fit(nominal()).save(tmp_path / "m")
    code = ("import sys; from cclogfs.classifier.model import OneClassModel; "
            f"m = OneClassModel.load({str(path)!r}); "
            "print(sorted(k for k in sys.modules if k.split('.')[0] == 'sklearn'))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_too_little_data():
    with pytest.raises(ModelError, match="at least 20"):
        OneClassModel().fit(np.ones((5, 3)))
