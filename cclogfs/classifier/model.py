"""One-class SVM on standardized feature vectors, with a calibrated threshold.

Saved as a directory holding `model.json` (hyperparameters, threshold, feature config,
versions, checksum of the arrays) and `model.npz` (support vectors, dual coefficients,
intercept, scaler): no pickle, and inference is plain numpy.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import ModelError

__all__ = ["FORMAT", "FORMAT_VERSION", "OneClassModel"]

FORMAT = "cclogfs-ocsvm"
FORMAT_VERSION = 1
_ARRAYS = ("mean", "scale", "support_vectors", "dual_coef", "intercept")
_CHUNK = 4096  # rows per kernel block: bounds memory for wide (paper) vectors


def _blocks(n: int, rows: int):
    for a in range(0, n, rows):
        yield slice(a, min(a + rows, n))


class OneClassModel:
    """RBF one-class SVM; `score(X) > 0` means anomalous.

    Without labelled anomalies, `nu` and `gamma` default to 0.01 and 0.1/n_features (after
    standardization; a smooth boundary generalizes better from minutes of driving). With anomalies, they are chosen on a grid by recall on the anomalies
    at the calibrated threshold. The threshold is the `false_alarm_rate` quantile of the
    decision values of held-out nominal vectors (blocks of consecutive vectors, so the
    held-out data is not a near copy of the training data), lowered by `margin` x rho.
    """

    def __init__(
        self,
        *,
        feature_config: dict | None = None,
        nu: float | None = None,
        gamma: float | None = None,
        false_alarm_rate: float = 0.001,
        margin: float = 0.15,
        holdout: float = 0.25,
        block: int = 64,
        max_train: int = 4000,
        min_scale: np.ndarray | float = 1e-9,
        one_sided: bool = False,
        nu_grid: tuple[float, ...] = (0.002, 0.01, 0.05),
        gamma_grid: tuple[float, ...] = (0.03, 0.1, 0.3, 1.0),
        random_state: int = 0,
        topic: str = "/odom",
    ):
        self.feature_config = feature_config
        self.topic = topic  # the odometry topic the model watches, kept in the model file
        self.training: dict | None = None  # classifier.fit.robot_stats of the training runs
        self.nu = nu
        self.gamma = gamma
        self.false_alarm_rate = false_alarm_rate
        self.margin = margin
        self.holdout = holdout
        self.block = block
        self.max_train = max_train
        self.min_scale = min_scale
        self.one_sided = one_sided
        self.nu_grid = nu_grid
        self.gamma_grid = gamma_grid
        self.random_state = random_state
        # Second stage (set by the caller after `fit`, None: none): per feature, the value
        # a vector must exceed in at least one feature for a flag to stand.
        self.limits_: np.ndarray | None = None
        # How the limits grow online (0: they do not; see `score`): to this many times the
        # largest value the robot has shown while the SVM judged it nominal.
        self.limit_growth_ = 0.0

    # -- training ---------------------------------------------------------------------

    def fit(self, X: np.ndarray, X_anomalous: np.ndarray | None = None) -> OneClassModel:
        """Train on nominal vectors X; anomalous vectors, if given, only select nu/gamma."""
        X = np.asarray(X, dtype=np.float64)
        X = X[np.isfinite(X).all(axis=1)]
        if X.ndim != 2 or len(X) < 20:
            raise ModelError(f"Training needs at least 20 finite nominal vectors, got {len(X)}.")
        train, hold = self.split(X)
        self.mean_ = train.mean(axis=0)
        self.scale_ = np.maximum(train.std(axis=0), self.min_scale)
        self.n_features_in_ = X.shape[1]
        dim = X.shape[1]
        if X_anomalous is not None and len(X_anomalous):
            Xa = np.asarray(X_anomalous, dtype=np.float64)
            Xa = Xa[np.isfinite(Xa).all(axis=1)]
            best = None
            for nu in (self.nu,) if self.nu else self.nu_grid:
                for g in (self.gamma,) if self.gamma else [f / dim for f in self.gamma_grid]:
                    self._fit_svm(train, nu, g, hold)
                    s_anom = self.score(Xa)
                    spread = np.median(-self.score(hold)) + 1e-12
                    key = (np.mean(s_anom > 0), np.median(s_anom) / spread)
                    if best is None or key > best[0]:
                        best = (key, nu, g)
            _, nu, g = best
            self.validation_recall_ = float(best[0][0])
        else:
            nu, g = self.nu or 0.01, self.gamma or 0.1 / dim
        self._fit_svm(train, nu, g, hold)
        self.n_train_ = len(train)
        self.model_id_ = self._digest()[:16]
        return self

    def split(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(training rows, held-out rows) of X, as `fit` uses them (deterministic)."""
        rng = np.random.default_rng(self.random_state)
        blocks = np.arange(len(X)) // self.block
        n_blocks = int(blocks[-1]) + 1
        n_hold = max(1, int(round(n_blocks * self.holdout))) if n_blocks > 1 else 0
        held = np.isin(blocks, rng.choice(n_blocks, n_hold, replace=False))
        if not held.any() or held.all():  # too little data for blocks: hold out every 4th
            held = np.arange(len(X)) % 4 == 0
        train, hold = X[~held], X[held]
        if len(train) > self.max_train:  # evenly spaced in time keeps rare manoeuvres
            train = train[np.linspace(0, len(train) - 1, self.max_train).round().astype(int)]
        return train, hold

    def _fit_svm(self, train: np.ndarray, nu: float, gamma: float, hold: np.ndarray) -> None:
        from sklearn.svm import OneClassSVM

        svm = OneClassSVM(kernel="rbf", nu=nu, gamma=gamma, cache_size=100)
        svm.fit(self.transform(train))
        self.nu_, self.gamma_ = float(nu), float(gamma)
        self.support_vectors_ = np.ascontiguousarray(svm.support_vectors_)
        self.dual_coef_ = np.ascontiguousarray(svm.dual_coef_[0])
        self.intercept_ = float(svm.intercept_[0])
        # Held-out blocks still resemble the training run more than tomorrow's driving does,
        # so "anomalous" means clearly outside: a margin in units of rho, the decision value
        # of a vector far from all training data.
        self.threshold_ = 0.0
        q = float(np.quantile(self.decision_function(hold), self.false_alarm_rate))
        self.threshold_ = q - self.margin * max(-self.intercept_, 1e-12)

    # -- inference --------------------------------------------------------------------

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Standardized vectors; one-sided models count only values above the mean."""
        Z = (X - self.mean_) / self.scale_
        return np.maximum(Z, 0.0) if self.one_sided else Z

    def decision_function(self, X: np.ndarray) -> np.ndarray:
        """sklearn OneClassSVM.decision_function in numpy: negative means outside."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        sv = self.support_vectors_
        sv_sq = np.einsum("ij,ij->i", sv, sv)
        out = np.empty(len(X))
        for rows in _blocks(len(X), _CHUNK):
            Z = self.transform(X[rows])
            d2 = np.einsum("ij,ij->i", Z, Z)[:, None] + sv_sq[None, :] - 2.0 * (Z @ sv.T)
            out[rows] = np.exp(-self.gamma_ * np.maximum(d2, 0.0)) @ self.dual_coef_
        return out + self.intercept_

    def score_one(self, x: np.ndarray, limits: np.ndarray | None = None) -> float:
        """`score` of one vector with few numpy calls (the live path, once per message);
        `limits` as in `score`, grown in place."""
        sv = self.support_vectors_
        if getattr(self, "_sv_of", None) is not sv:
            self._sv_of, self._sv_sq = sv, np.einsum("ij,ij->i", sv, sv)
        z = (x - self.mean_) / self.scale_
        if self.one_sided:
            np.maximum(z, 0.0, out=z)
        d2 = np.maximum(z @ z + self._sv_sq - 2.0 * (sv @ z), 0.0)
        d = float(np.exp(-self.gamma_ * d2) @ self.dual_coef_) + self.intercept_
        s = (self.threshold_ - d) / max(-self.intercept_, 1e-12)
        if self.limits_ is not None:
            over = float(np.max(x / (self.limits_ if limits is None else limits))) - 1.0
            if limits is not None and s <= 0.0 and self.limit_growth_ > 0:
                g = self.limit_growth_
                np.maximum(limits, x if g == 1.0 else g * x, out=limits)
            s = min(s, over)
        return s

    def score(self, X: np.ndarray, limits: np.ndarray | None = None) -> np.ndarray:
        """Anomaly score: how far below the threshold, in units of rho (so comparable
        across models); > 0 is anomalous, NaN rows give NaN. With limits (the second
        stage), the smaller of that and how far the vector's largest feature is beyond
        its limit (a fraction of the limit): both must say anomalous.

        `limits`: the robot's limits now (per feature, at least `limits_`; grown in place;
        None: `limits_`, and the rows are scored independently). X is then a run in time
        order and the limits grow online (`limit_growth_` > 0): each row is judged by the
        limits left by the rows before it, and a row the SVM judges nominal raises every
        limit to at least `limit_growth_` x its value. Two minutes of training miss some
        of a robot's ordinary manoeuvres; when the SVM later sees them as nominal, the
        limits stop flagging them. A vector the SVM flags never raises a limit, so an
        anomaly is not learnt from."""
        s = self.svm_score(X)
        if self.limits_ is None:
            return s
        X = np.atleast_2d(X)
        return np.minimum(s, np.max(X / self.row_limits(X, s, limits), axis=1) - 1.0)

    def svm_score(self, X: np.ndarray) -> np.ndarray:
        """The first stage of `score` alone: how far below the SVM's threshold, in rho."""
        return (self.threshold_ - self.decision_function(X)) / max(-self.intercept_, 1e-12)

    def row_limits(self, X: np.ndarray, svm: np.ndarray, limits: np.ndarray | None = None) -> np.ndarray:
        """The limits each row of X is judged by in `score` (`svm`: its `svm_score`):
        `limits_` when `limits` is None, else `limits` grown row by row (and in place)."""
        if limits is None:
            return self.limits_
        if self.limit_growth_ > 0 and len(X):
            seen = np.where((svm <= 0.0)[:, None], self.limit_growth_ * np.nan_to_num(X, nan=0.0), 0.0)
            np.maximum.accumulate(seen, axis=0, out=seen)
            np.maximum(seen, limits, out=seen)  # the limits after each row
            before = np.vstack([limits, seen[:-1]])
            limits[:] = seen[-1]
            return before
        return limits

    def predict(self, X: np.ndarray) -> np.ndarray:
        """True where a vector is anomalous."""
        return self.score(X) > 0

    # -- persistence ------------------------------------------------------------------

    def _arrays(self) -> dict[str, np.ndarray]:
        out = {
            "mean": self.mean_, "scale": self.scale_, "support_vectors": self.support_vectors_,
            "dual_coef": self.dual_coef_, "intercept": np.array([self.intercept_]),
        }  # fmt: skip
        if self.limits_ is not None:
            out["limits"] = self.limits_
        return out

    def set_limits(self, limits: np.ndarray | None, growth: float = 0.0) -> OneClassModel:
        """Set the second stage (None: none), how its limits grow online (`score`; 0:
        they do not) and the model id, which covers both."""
        if not growth >= 0:
            raise ModelError(f"Limit growth must be >= 0, got {growth!r}.")
        self.limit_growth_ = float(growth) if limits is not None else 0.0
        self.limits_ = None if limits is None else np.asarray(limits, dtype=np.float64)
        if self.limits_ is not None and (self.limits_.shape != (self.n_features_in_,) or not (self.limits_ > 0).all()):
            raise ModelError(f"Limits need {self.n_features_in_} positive values, got {self.limits_}.")
        self.model_id_ = self._digest()[:16]
        return self

    def _header(self, *, versions: bool = True) -> dict:
        """model.json's fields. `versions=False` leaves out the library versions, which the
        model id does not cover: the check on load then imports no scikit-learn, which
        scoring never needs (importing it cost `record --model` ~2 s and ~75 MiB)."""
        out = {
            "format": FORMAT, "format_version": FORMAT_VERSION,
            "feature_config": self.feature_config, "n_features": int(self.n_features_in_),
            "gamma": self.gamma_, "nu": self.nu_, "threshold": self.threshold_,
            "one_sided": bool(self.one_sided),
            "false_alarm_rate": self.false_alarm_rate, "n_support": len(self.dual_coef_),
            "n_train": int(self.n_train_), "topic": self.topic, "training": self.training,
        }  # fmt: skip
        if versions:
            import sklearn

            out["versions"] = {"cclogfs": __version__, "numpy": np.__version__, "sklearn": sklearn.__version__}
        if self.limit_growth_:  # absent: fixed limits (files written before it existed)
            out["limit_growth"] = self.limit_growth_
        return out

    def _digest(self) -> str:
        h = hashlib.sha256()
        for name, arr in self._arrays().items():
            h.update(name.encode())
            h.update(np.ascontiguousarray(arr, dtype="<f8").tobytes())
        # "training" (statistics for a warning) does not change what the model computes.
        h.update(json.dumps({k: v for k, v in self._header(versions=False).items() if k != "training"},
                            sort_keys=True).encode())  # fmt: skip
        return h.hexdigest()

    def save(self, path: str | Path) -> Path:
        """Write `path/model.npz` and `path/model.json` (each via temp file and rename)."""
        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez(buf, **{k: np.asarray(v, dtype="<f8") for k, v in self._arrays().items()})
        blob = buf.getvalue()
        header = self._header() | {
            "model_id": self.model_id_, "npz_sha256": hashlib.sha256(blob).hexdigest(),
        }
        for name, data in (("model.npz", blob), ("model.json", json.dumps(header, indent=1).encode())):
            tmp = path / (name + ".tmp")
            with open(tmp, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path / name)
        return path

    @classmethod
    def load(cls, path: str | Path, *, feature_config: dict | None = None) -> OneClassModel:
        """Read a saved model; ModelError if it is damaged, of another format version, or
        (when `feature_config` is given) made for other features."""
        path = Path(path)
        jpath, npath = path / "model.json", path / "model.npz"
        try:
            header = json.loads(jpath.read_text())
            blob = npath.read_bytes()
        except (OSError, ValueError) as err:
            raise ModelError(f"Cannot read model {path}: {err}.") from err
        if not isinstance(header, dict) or header.get("format") != FORMAT:
            raise ModelError(f"{jpath} is not a {FORMAT} model file (field 'format').")
        if header.get("format_version") != FORMAT_VERSION:
            raise ModelError(
                f"{jpath} has format_version {header.get('format_version')!r}; this cclogfs "
                f"reads version {FORMAT_VERSION}. Retrain the model."
            )
        if hashlib.sha256(blob).hexdigest() != header.get("npz_sha256"):
            raise ModelError(f"{npath} does not match the checksum in {jpath} (field 'npz_sha256').")
        if feature_config is not None and header.get("feature_config") != feature_config:
            raise ModelError(
                f"Model {path} was trained on features {header.get('feature_config')}, "
                f"not on {feature_config}. Retrain it for these features."
            )
        try:
            with np.load(io.BytesIO(blob), allow_pickle=False) as z:
                arrays = {k: z[k] for k in _ARRAYS}
                limits = z["limits"] if "limits" in z.files else None
            model = cls(feature_config=header["feature_config"], one_sided=header["one_sided"],
                        false_alarm_rate=header["false_alarm_rate"],
                        topic=str(header.get("topic", "/odom")))  # fmt: skip
            model.mean_, model.scale_ = arrays["mean"], arrays["scale"]
            model.support_vectors_, model.dual_coef_ = arrays["support_vectors"], arrays["dual_coef"]
            model.intercept_ = float(arrays["intercept"][0])
            model.gamma_, model.nu_ = float(header["gamma"]), float(header["nu"])
            model.threshold_ = float(header["threshold"])
            model.n_features_in_, model.n_train_ = int(header["n_features"]), int(header["n_train"])
            model.model_id_ = str(header["model_id"])
            model.training = header.get("training")  # absent in files written before it was kept
            model.limits_ = limits
        except (KeyError, ValueError, TypeError) as err:
            raise ModelError(f"Model {path} is malformed: missing or bad field {err}.") from err
        sv = model.support_vectors_
        if sv.ndim != 2 or sv.shape[1] != model.n_features_in_ or len(model.dual_coef_) != len(sv):
            raise ModelError(f"{npath}: support vector shapes do not match n_features/n_support.")
        if limits is not None and (limits.shape != (model.n_features_in_,) or not (limits > 0).all()):
            raise ModelError(f"{npath}: 'limits' must hold {model.n_features_in_} positive values.")
        growth = header.get("limit_growth", 0.0)
        if not isinstance(growth, (int, float)) or not growth >= 0 or (growth and limits is None):
            raise ModelError(f"{jpath}: 'limit_growth' must be a number >= 0, and needs limits in {npath}.")
        model.limit_growth_ = float(growth)
        # model.json has no checksum of its own: a changed threshold, gamma or feature
        # parameter loaded without a word. The model id covers them; compute it again.
        if model._digest()[:16] != model.model_id_:
            raise ModelError(f"{jpath} does not match its model_id (field 'model_id'): a value the model "
                             "computes with was changed or damaged; retrain the model.")  # fmt: skip
        return model
