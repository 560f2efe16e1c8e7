"""Entry points for the pipeline and CLI: train, detect, build logging windows, collect."""

from __future__ import annotations

import json
import math
from itertools import accumulate, chain, repeat
from operator import eq, is_not, itemgetter
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np

from ..errors import InvalidInputError, ModelError
from .evidence import EvidenceHistory, evidence_back
from .features import OdomArrays, TwistFromPoses, make_features, odom_row, odom_rows_compiled, parse_odometry
from .fit import robot_stats, speed_noise
from .model import OneClassModel
from .summary import SUMMARY_TOPIC, SummaryBuilder
from .windows import PendingWindow, WindowBuilder

__all__ = ["Detector", "SmartLogger", "collect", "event_masks", "load_dataset", "parse_labels", "train"]

# Noise floors of the default features (rad/s, m/s^2, rad/s^2, m/s, ...), in the order of
# features.DEFAULT_NAMES: standardizing by a spread smaller than this would make sensor
# noise look anomalous on a robot other than the one the model was trained on.
# direction_reversals is a count: 0.3 makes 2-4 reversals in 8 s (mild `stuck` nudges)
# stand out, while a base that never reverses in training still gets a finite scale.
DEFAULT_FLOORS = np.array([0.3, 0.3, 0.3, 1.0, 0.1, 0.005, 0.02, 0.02, 0.5, 1.0, 0.3])


def _as_odom(source) -> OdomArrays:
    return source if isinstance(source, OdomArrays) else parse_odometry(source)


def parse_labels(labels) -> list[dict]:
    if labels is None:
        return []
    try:
        events = labels["events"] if isinstance(labels, dict) else labels
        out = [{"start_ns": int(e["start_ns"]), "end_ns": int(e["end_ns"]),
                "kind": str(e.get("kind", ""))} for e in events]  # fmt: skip
    except (KeyError, TypeError, ValueError) as err:
        raise InvalidInputError(
            f"Labels must be {{'events': [{{'start_ns', 'end_ns', 'kind'}}]}}: bad field {err}."
        ) from err
    for i, e in enumerate(out):
        if e["end_ns"] < e["start_ns"]:  # it would cover no message: an event missed, in silence
            raise InvalidInputError(f"Labels: event {i + 1} ends before it starts "
                                    f"(start_ns {e['start_ns']} > end_ns {e['end_ns']}).")  # fmt: skip
    return out


def event_masks(features, stamp_ns: np.ndarray, labels) -> tuple[np.ndarray, np.ndarray]:
    """(inside, touched): messages inside a labelled event, and messages whose feature
    vector depends on one (inside, or within the feature window after it)."""
    inside = np.zeros(len(stamp_ns), dtype=bool)
    touched = np.zeros(len(stamp_ns), dtype=bool)
    for e in parse_labels(labels):
        a = np.searchsorted(stamp_ns, e["start_ns"], side="left")
        b = np.searchsorted(stamp_ns, e["end_ns"], side="right")
        inside[a:b] = True
        if hasattr(features, "horizon_ns"):
            c = np.searchsorted(stamp_ns, e["end_ns"] + features.horizon_ns, side="right")
        else:  # window of messages
            c = b + features.span - 1
        touched[a:c] = True
    return inside, touched


# A robot whose speed changes by more than this (robust standard deviation over 0.1 s,
# m/s) without driving so is noisy: TUC's wheel odometry 0.002-0.004, the slamfail robots'
# twist differenced from poses 0.05-0.14 (both at 10-100 Hz). Its twist is despiked over
# NOISY_DESPIKE_S (issue 15, fifth pass; on the long runs' tuning placements the false
# windows of those robots fell from 4.5 to 1.4 per 10 min at native rate, with 3 more
# events recalled; 0.15-0.25 s and 0.4 s did worse, docs/CLASSIFIER.md).
NOISY_SPEED = 0.02
NOISY_DESPIKE_S = 0.3


def robot_thresholds(runs: list[OdomArrays], noisy_despike_s: float = NOISY_DESPIKE_S) -> dict:
    """Default-feature thresholds learnt from the robot's own odometry (`fit.speed_noise`,
    the robust spread of its speed's change over 0.1 s):
    - a forward/backward flip must stand out of that noise (4 robust standard deviations),
      never less than the fixed 0.01 m/s. Twist differenced from poses (the slamfail
      robots) jitters by 0.05-0.14 m/s and otherwise "reverses" ten times a second while it
      crawls; wheel odometry (TUC) keeps 0.01. Until issue 15's fifth pass the noise was
      the change from one message to the next, which shrinks with the message rate: at
      30 and 100 Hz the flip threshold fell 3x and 9x and the noise "reversed" again.
    - a robot whose speed noise is above NOISY_SPEED gets its twist despiked over
      `noisy_despike_s` instead of 0.1 s (0: not): the median of the values now, that long
      ago and twice that, so that a jitter of a few messages no longer passes while an
      event held 0.4 s and more (the injected ones: 0.5-6 s) passes, 0.3 s later.
    Measured in bench/classifier_long.py (docs/CLASSIFIER.md, fifth pass)."""
    noise = speed_noise(runs)
    if noise is None:
        return {}
    out = {"dir_flip": max(0.01, 4 * noise)}
    if noise > NOISY_SPEED and noisy_despike_s:
        out["despike_s"] = float(noisy_despike_s)
    return out


# The second stage's default: a flag stands only where some feature is beyond this many
# times the most the robot showed in training (or the feature's noise floor).
LIMIT_FACTOR = 1.5
# ... and the limits grow online to LIMIT_GROWTH x the largest values the robot shows while
# the SVM judges it nominal (`OneClassModel.score`; issue 15, fourth pass): on the long
# real runs' tuning seeds, 8-21 % fewer false windows at 10-100 Hz and the same events
# recalled; 1.2 and more lost mild events (docs/CLASSIFIER.md).
LIMIT_GROWTH = 1.0


# The least limit per default feature, whatever training showed: manoeuvres of the TUC
# robot's ordinary driving that its first 2 minutes happened not to show
# (bench/classifier_long.py): stops at goals (0.41 m/s to 0 in 0.2 s, up to 2.6 m/s^2;
# an injected collision at 10 Hz is 4 m/s^2, the TurtleBot's 0.3 m/s stop in one message
# at 28 Hz 3.5 m/s^2 after the despike), a U-turn in place (pi rad; a spin is more), the
# angular acceleration of starting one (up to 2.5 rad/s^2), and the few cm/s (rad/s) by
# which pose and twist disagree under the best integration scheme (features version 6;
# the slamfail robots' poses: up to 0.03 m/s in one message; version 5, the trapezoid
# alone, saw the TUC robot's scheme disagree by up to 0.07 m/s). Injected slips and pose
# jumps start at 0.16 and 0.4 m/s of mismatch.
LIMIT_MIN = np.array([0.0, 0.0, 3.0, 3.0, 0.0, 0.0, 0.08, 0.1, np.pi, 0.0, 0.0])


def robot_limits(X: np.ndarray, factor: float, tail_factor: float = 0.0) -> np.ndarray:
    """Per default feature, `factor` x the largest value in the nominal vectors X (at least
    the noise floor): a flag that no feature confirms beyond its limit is the robot doing
    what it did in training, only a little more. Braking is limited by the larger of the
    speed-up and braking limits: a base that can speed up at 1 m/s^2 can stop as hard,
    whether or not the training minutes showed a stop. None is below LIMIT_MIN.

    `tail_factor` > 0 (off by default): also at least that many times the 99th percentile,
    the tail of the robot's own noise extrapolated to runs longer than training (for
    exponential tails the maximum over 25,000 messages is ~2.2x the 99th percentile).
    It buys precision with recall, as a larger `factor` does (docs/CLASSIFIER.md)."""
    top = np.maximum(np.nanmax(X, axis=0) if len(X) else 0.0, DEFAULT_FLOORS)
    out = factor * top
    if tail_factor and len(X):
        out = np.maximum(out, tail_factor * np.nanquantile(X, 0.99, axis=0))
    out[2] = max(out[1], out[2])
    return np.maximum(out, LIMIT_MIN)


def train(
    sources: Iterable, *, labels=None, features: dict | str | None = "default",
    limit_factor: float | None = LIMIT_FACTOR, tail_factor: float = 0.0,
    limit_growth: float = LIMIT_GROWTH, noisy_despike_s: float = NOISY_DESPIKE_S,
    deriv_s: float | None = None, **params,
) -> OneClassModel:  # fmt: skip
    """A model trained on odometry runs (OdomArrays, or lists of JSON texts/dicts).

    `labels`: None, one {"events": [...]} for all runs (stamps are absolute), or a list
    with one per run. Vectors that depend on an event are left out of the nominal set; the
    ones inside events select nu/gamma. `params` go to OneClassModel. Default features get
    a second stage (`robot_limits` with `limit_factor` and `tail_factor`; None or 0: none)
    whose limits grow online by `limit_growth` (0: fixed limits). The default features are
    calibrated to the robot's noise (`robot_thresholds`, with `noisy_despike_s`).
    """
    sources = [_as_odom(s) for s in sources]
    feature_set = make_features(features)
    if features in ("default", None):  # calibrated to this robot; an explicit config is kept
        calibrated = robot_thresholds(sources, noisy_despike_s) | ({"deriv_s": deriv_s} if deriv_s else {})
        feature_set = make_features(feature_set.get_config() | {"params": feature_set.params | calibrated})
    per_run = labels if isinstance(labels, list) else [labels] * len(sources)
    if len(per_run) != len(sources):
        raise InvalidInputError(f"Got {len(per_run)} label sets for {len(sources)} runs.")
    nominal, anomalous = [], []
    for odom, lab in zip(sources, per_run):
        X, valid = feature_set.batch(odom)
        inside, touched = event_masks(feature_set, odom.stamp_ns, lab)
        nominal.append(X[valid & ~touched])
        anomalous.append(X[valid & inside])
    if feature_set.id == "default":
        params.setdefault("min_scale", DEFAULT_FLOORS)
        params.setdefault("one_sided", True)
    model = OneClassModel(feature_config=feature_set.get_config(), **params)
    model.training = robot_stats(sources)
    Xa = np.concatenate(anomalous)
    Xn = np.concatenate(nominal)
    model.fit(Xn, Xa if len(Xa) else None)
    if feature_set.id == "default" and limit_factor:
        model.set_limits(robot_limits(Xn[np.isfinite(Xn).all(axis=1)], limit_factor, tail_factor), limit_growth)
    return model


class Detector:
    """Scores odometry with a model: whole runs (`score_batch`) or live (`update`)."""

    def __init__(self, model: OneClassModel):
        self.model = model
        self.features = make_features(model.feature_config)
        if self.features.dim != model.n_features_in_:
            raise ModelError(
                f"Model {model.model_id_} expects {model.n_features_in_} features, but its "
                f"feature set {model.feature_config} gives {self.features.dim}."
            )
        # Per feature column, how far back its evidence reaches (None: not known).
        self.spans_ns = getattr(self.features, "spans_ns", None)
        self.lookback_max_s = 0.0 if self.spans_ns is None else float(self.spans_ns.max()) / 1e9
        # The long columns, whose evidence start is tracked (`classifier.evidence`).
        self.counted = getattr(self.features, "counted", ()) if self.spans_ns is not None else ()
        self.last_vector: np.ndarray | None = None
        self.last_back: np.ndarray | None = None  # the newest vector's `evidence`, if flagged
        self.reset()

    def reset(self) -> None:
        self._stream = self.features.stream()
        # (vector as any sequence of floats, valid): the compiled stream's tuples, no array each
        self._push_values = getattr(self._stream, "values", self._stream.push)
        self._twist = TwistFromPoses()
        # The robot's limits now: the model's, grown live (`OneClassModel.score`).
        self.limits = None if self.model.limits_ is None else self.model.limits_.copy()
        # Where the long columns' evidence starts, live (runs of nonzero values per column).
        self.evidence = EvidenceHistory(self.counted, self.spans_ns[list(self.counted)],
                                        self.features.evidence_margin_ns) if self.counted else None  # fmt: skip

    def lookback_ns(self, X: np.ndarray, backs=None) -> np.ndarray:
        """Per vector, how long before its message the anomaly's evidence starts: the
        longest among the features that stand out most (at least half the top
        standardized deviation). A jolt seen by the 0.5 s maxima started half a second
        ago; a spin seen by its net rotation over 8 s, where that rotation began: `backs`,
        per vector the long columns' own evidence (`classifier.evidence`). Without
        `backs`, their whole span."""
        X = np.atleast_2d(X)
        if self.spans_ns is None or not len(X):
            return np.zeros(len(X), dtype=np.int64)
        Z = np.nan_to_num(np.abs(self.model.transform(X)))
        involved = (Z > 0) & (Z >= 0.5 * Z.max(axis=1, keepdims=True))
        spans = np.broadcast_to(self.spans_ns, X.shape)
        if backs is None or not self.counted:
            return np.where(involved, spans, 0).max(axis=1)
        # A slow anomaly shows in several long columns, not all standing out as much: its
        # evidence starts where the earliest of them began, but never further back than
        # the column that stands out looks (its span, as before the seventh pass).
        longs = list(self.counted)
        spans = spans.copy()
        spans[:, longs] = np.minimum(spans[:, longs], np.max(backs, axis=1, keepdims=True))
        return np.where(involved, spans, 0).max(axis=1)

    def score_windows(self, odom) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(scores, anomalous, lookback_ns) per message, for a whole run."""
        odom = _as_odom(odom)
        X, valid = self.features.batch(odom)
        scores = np.full(len(odom), np.nan)
        if valid.any():  # the limits grow over this run alone, as from a fresh detector
            fresh = None if self.model.limits_ is None else self.model.limits_.copy()
            scores[valid] = self.model.score(X[valid], fresh)
        flags = np.nan_to_num(scores, nan=-np.inf) > 0
        lookback = np.zeros(len(odom), dtype=np.int64)
        backs = None
        if self.counted and flags.any():
            cols = list(self.counted)
            backs = evidence_back(odom.stamp_ns, X[:, cols], valid, self.spans_ns[cols],
                                  self.features.evidence_margin_ns)[flags]  # fmt: skip
        lookback[flags] = self.lookback_ns(X[flags], backs)
        return scores, flags, lookback

    def score_batch(self, odom) -> tuple[np.ndarray, np.ndarray]:
        """(scores, anomalous) per message; NaN score and False where no vector exists."""
        return self.score_windows(odom)[:2]

    def vector(self, stamp_ns: int, row) -> np.ndarray | tuple | None:
        """The newest message's feature vector, an array or a tuple of floats (None while
        there is none or it is not valid). A valid one also goes to `evidence`, whose
        `take` the caller then calls for it (SmartLogger does, a batch at a time)."""
        got = self._push_values(stamp_ns, row)
        if got is None or not got[1]:
            return None
        if self.evidence is not None:
            self.evidence.append(stamp_ns, got[0])
        return got[0]

    def update_row(self, stamp_ns: int, row) -> tuple[float, bool]:
        """Score of the newest message given as (stamp, 13 raw values)."""
        got = self._stream.push(stamp_ns, row)
        if got is None or not got[1]:
            return math.nan, False
        self.last_vector = got[0]
        score = self.model.score_one(got[0], self.limits)
        if self.evidence is not None:  # the long columns' evidence, for `lookback_ns`
            self.evidence.append(stamp_ns, got[0])
            self.last_back = self.evidence.take(1, (0,) if score > 0 else ())
        return score, score > 0

    def parse(self, msg: dict | str | bytes) -> tuple[int, tuple[float, ...]]:
        """(stamp, 13 raw values) of one live odometry or pose message (twist from poses)."""
        stamp, row = odom_row(msg)
        return stamp, self._twist(stamp, row)

    def update(self, msg: dict | str | bytes) -> tuple[float, bool]:
        """Score of one live odometry message (rosbridge dict or JSON text)."""
        return self.update_row(*self.parse(msg))


# Windows in seconds mode (bench/classifier_long.py, issue 15): an anomaly whose context
# comes within MERGE_S of a closed window joins it (a collision's stop and its restart up
# to 4 s later stay one window), and a window stays open while the score is above
# HOLD_SCORE (hysteresis: the tail of a mild event scores just below 0), so that the
# context after can be short. MERGE_S was 3 s with 2 s before and 1 s after
# (pipeline.WINDOW_BEFORE, WINDOW_AFTER); with 1 s and 0.5 s it is 4.5 s, so that flags
# as far apart as before stay one window (sixth pass: the same windows, each shorter).
MERGE_S = 4.5
HOLD_SCORE = -0.3


class SmartLogger:
    """Turns a stream of (topic, stamp_ns, json_text) into PendingWindows to store.

    Odometry on `odom_topic` is scored; windows come from WindowBuilder (same keyword
    arguments); per-minute summaries come out as windows on `/cclog/summary`. With
    `batch` > 1, features are still computed per message but the SVM scores up to `batch`
    held messages at once: the same windows, closing up to `batch` messages later.
    """

    def __init__(self, detector: Detector, *, odom_topic: str = "/odom",
                 summary_period_s: float | None = 60.0, batch: int = 1, **window_args):  # fmt: skip
        if batch < 1:
            raise InvalidInputError(f"batch must be at least 1, not {batch!r}.")
        self.batch = batch
        self._pending: list[tuple] = []  # messages held until their odometry is scored
        self._held_other = False  # whether _pending holds a message of another topic
        self._vectors: list = []  # their feature vectors (Detector.vector)
        self.detector = detector
        self.odom_topic = odom_topic
        window_args.setdefault("lookback_max_s", detector.lookback_max_s)
        window_args.setdefault("merge_s", MERGE_S)
        # The level is in the two-stage score's units: a model without limits (older
        # files, limit_factor=0) scores ordinary driving above it, and would keep all.
        window_args.setdefault("hold_score", HOLD_SCORE if detector.model.limits_ is not None else None)
        self.windows = WindowBuilder(trigger_topic=odom_topic,
                                     model_id=detector.model.model_id_, **window_args)  # fmt: skip
        self.summary = SummaryBuilder(period_s=summary_period_s) if summary_period_s else None
        # A score at or below this is neither an anomaly nor above the hold level (`_scores`).
        hold = self.windows.hold_score
        self._quiet_below = 0.0 if hold is None else min(0.0, hold)
        self.scored = 0
        self.anomalies = 0

    def push(self, topic: str, stamp_ns: int, text: str) -> list[PendingWindow]:
        """One message; returns the windows (and summaries) that closed."""
        if topic != self.odom_topic:
            if self._pending:
                self._pending.append((topic, stamp_ns, text, None, False))
                self._held_other = True
                return []
            return self.windows.push(topic, stamp_ns, text)
        head, row = self.detector.parse(text)
        if self.batch == 1:
            score, flag = self.detector.update_row(head, row)
            det = self.detector
            back = int(det.lookback_ns(det.last_vector, det.last_back)[0]) if flag else 0
            return self._odom(stamp_ns, text, row, score, flag, back)
        vec = self.detector.vector(head, row)
        if vec is not None:
            self._vectors.append(vec)
        self._pending.append((topic, stamp_ns, text, row, vec is not None))
        return self._drain() if len(self._pending) >= self.batch else []

    def push_many(self, messages: Sequence, rows: list | None = None) -> list[PendingWindow]:
        """`push` of each (topic, stamp_ns, text, ...) in turn: the same windows in the same
        order, the SVM scoring the same groups of `batch` held messages. For a source that
        hands over many messages at once (issue 14): the compiled reader reads the list's
        odometry in one call, and the windows and summaries take the held odometry a
        stretch at a time (`_drain`). `rows`: that call's result when the caller made it
        already (the pipeline reads the odometry first to keep what cannot be scored)."""
        if self.batch == 1 or not messages:
            return [w for m in messages for w in self.push(m[0], m[1], m[2])]
        odom_topic, pending, vectors, batch = self.odom_topic, self._pending, self._vectors, self.batch
        parse, vector = self.detector.parse, self.detector.vector
        if all(map(eq, map(itemgetter(0), messages), repeat(odom_topic))):  # a run of odometry alone
            got = rows if rows is not None else odom_rows_compiled(list(map(itemgetter(2), messages)))
            if None not in got:
                return self._push_odometry(messages, got)
            read = iter(got)
        else:
            read = iter(rows if rows is not None else
                        odom_rows_compiled([m[2] for m in messages if m[0] == odom_topic]))  # fmt: skip
        out: list[PendingWindow] = []
        for m in messages:
            topic, stamp_ns, text = m[0], m[1], m[2]
            if topic != odom_topic:
                if pending:
                    pending.append((topic, stamp_ns, text, None, False))
                    self._held_other = True
                else:
                    out += self.windows.push(topic, stamp_ns, text)
                continue
            # A row of the compiled reader has a twist (`parse` would pass it unchanged);
            # `parse` reads the others, and raises at the message a bad one is.
            head, row = next(read) or parse(text)
            vec = vector(head, row)
            if vec is not None:
                vectors.append(vec)
            pending.append((topic, stamp_ns, text, row, vec is not None))
            if len(pending) >= batch:
                out += self._drain()
        return out

    def _push_odometry(self, messages: Sequence, got: list[tuple]) -> list[PendingWindow]:
        """`push_many` of odometry messages all read by the compiled reader (`got`, the
        (stamp, row) of each): the drains their pushes would make, made at once."""
        heads, rows = zip(*got)
        vecs = list(map(self.detector.vector, heads, rows))
        held = list(zip(map(itemgetter(0), messages), map(itemgetter(1), messages), map(itemgetter(2), messages),
                        rows, map(is_not, vecs, repeat(None))))  # fmt: skip
        # `push` drains when an odometry message brings the held ones to `batch` (more, when
        # messages of other topics came in between): the list's drains are done at once,
        # `_drain` scoring each group as its own drain would; the messages after the last
        # wait for the next list.
        p, b, n = len(self._pending), self.batch, len(held)
        first = max(1, b - p)  # the message whose push drains first
        if first > n:
            k, groups = 0, []
        else:
            groups = [p + first] + [b] * ((n - first) // b)
            k = first + (len(groups) - 1) * b
        out: list[PendingWindow] = []
        if k:
            self._vectors += [v for v in vecs[:k] if v is not None]
            self._pending += held[:k]
            out = self._drain(groups)
        self._vectors += [v for v in vecs[k:] if v is not None]
        self._pending += held[k:]
        return out

    def _drain(self, groups: list[int] | None = None) -> list[PendingWindow]:
        """Score the held odometry vectors at once, then run the windows over the held
        messages. `groups`: the held messages as consecutive drains would take them (counts),
        each scored alone (`_batch_scores`); None: one drain."""
        vectors = self._vectors
        if vectors and type(vectors[0]) is tuple:  # the compiled stream's: 2x faster than np.array
            V = np.fromiter(chain.from_iterable(vectors), np.float64, len(vectors) * len(vectors[0]))
            V = V.reshape(len(vectors), -1)
        else:
            V = np.array(vectors)
        s = self._batch_scores(V, groups)
        flagged = s > 0
        back = np.zeros(len(s), dtype=np.int64)
        evidence = self.detector.evidence
        if flagged.any():
            at = np.nonzero(flagged)[0]
            backs = None if evidence is None else evidence.take(len(s), at)
            back[flagged] = self.detector.lookback_ns(V[flagged], backs)
        elif evidence is not None:
            evidence.take(len(s))
        held, scores, backs = self._pending, s.tolist(), back.tolist()
        if len(scores) < len(held) or self._held_other:  # some without a score, or of another topic
            found = iter(zip(scores, backs))
            scores, backs = zip(*[next(found) if m[4] else (math.nan, 0) for m in held]) if held else ((), ())
        out: list[PendingWindow] = []
        i = 0
        while i < len(held):  # each stretch of odometry at once, the other messages one by one
            if held[i][3] is None:
                out += self.windows.push(*held[i][:3])
                i += 1
                continue
            j = i + 1
            if self._held_other:
                while j < len(held) and held[j][3] is not None:
                    j += 1
            else:
                j = len(held)
            out += self._odom_run(held[i:j], scores[i:j], backs[i:j])
            i = j
        self._pending.clear()
        self._vectors.clear()
        self._held_other = False
        return out

    def _odom_run(self, held: list[tuple], scores: Sequence[float], backs: Sequence[int]) -> list[PendingWindow]:
        """`_odom` of each held odometry message (topic, stamp_ns, text, row, scored) in
        turn: the windows a stretch at a time (`WindowBuilder.push_run`), each summary
        after the windows of the messages up to the one that ended its period, as in `_odom`."""
        stamps = [m[1] for m in held]
        texts = [m[2] for m in held]
        scores = list(scores)
        flags = [s > 0 for s in scores]
        backs = list(backs)
        self.scored += len(held)
        self.anomalies += sum(flags)
        if self.summary is None:
            return self.windows.push_run(stamps, texts, flags, scores, backs)
        rows = [m[3] for m in held]
        speeds = list(map(math.hypot, [r[7] for r in rows], [r[8] for r in rows]))
        out: list[PendingWindow] = []
        a = 0
        for k, rec in self.summary.update_many(stamps, rows, speeds, flags):
            out += self.windows.push_run(stamps[a : k + 1], texts[a : k + 1], flags[a : k + 1], scores[a : k + 1],
                                         backs[a : k + 1])  # fmt: skip
            out.append(self._summary_window(rec))
            a = k + 1
        return out + self.windows.push_run(stamps[a:], texts[a:], flags[a:], scores[a:], backs[a:])

    def _batch_scores(self, V: np.ndarray, groups: list[int] | None) -> np.ndarray:
        """`_scores` of the held vectors, each group of held messages (`_drain`) scored as
        if drained alone: the SVM's last bits depend on the rows scored together. When no
        score of any can matter, the bound of all at once (row by row, the same numbers)."""
        if groups is None or len(groups) == 1 or not len(V):
            return self._scores(V)
        bound = self._quiet_bound(V)
        if bound is not None:
            return bound
        valid = list(map(itemgetter(4), self._pending))
        starts = [0, *accumulate(groups)]
        ends = list(accumulate(valid[a:e].count(True) for a, e in zip(starts, starts[1:])))
        # each group's rows copied: a fresh array, as a group drained alone scores
        return np.concatenate([self._scores(V[a:e].copy()) for a, e in zip([0, *ends[:-1]], ends)])

    def _scores(self, V: np.ndarray) -> np.ndarray:
        """The held vectors' scores, or where no score can matter, a bound on them.

        With limits, a score is at most how far the vector's largest feature is beyond its
        limit (`OneClassModel.score`, the second stage). When that bound is at or below
        every level the windows compare a score with (0, and the hold level) for every
        vector of the batch, the SVM is skipped (nine batches in ten on real driving) and
        the bound stands in: the same flags, holds and windows. Otherwise the whole batch
        is scored as before, never a subset: BLAS gives a subset of rows other last bits,
        and a window's peak_score must not change."""
        if not len(V):
            return np.empty(0)
        bound = self._quiet_bound(V)
        return bound if bound is not None else self.detector.model.score(V, self.detector.limits)

    def _quiet_bound(self, V: np.ndarray) -> np.ndarray | None:
        """The bound of `_scores` on each vector's score (row by row) when every one is at
        or below the levels that matter, else None: the SVM must score them."""
        model, limits = self.detector.model, self.detector.limits
        # Growing limits (`OneClassModel.score`) raise a limit only to `limit_growth_` x a
        # value the SVM judged nominal; with every vector within the limits and a growth of
        # at most 1x, no limit moves, so skipping the SVM leaves them as scoring would.
        if limits is not None and model.limit_growth_ <= 1.0 and len(V):
            bound = np.max(V / limits, axis=1) - 1.0
            if bound.max() <= self._quiet_below:  # False when any is NaN: then scored
                return bound
        return None

    def _odom(self, stamp_ns, text, row, score, flag, lookback_ns=0) -> list[PendingWindow]:
        self.scored += 1
        self.anomalies += flag
        out = self.windows.push(self.odom_topic, stamp_ns, text, anomalous=flag, score=score,
                                lookback_ns=lookback_ns)  # fmt: skip
        if self.summary is not None:
            recs = self.summary.update(stamp_ns, row[0], row[1], math.hypot(row[7], row[8]), flag)
            if recs:  # once a minute
                out += [self._summary_window(r) for r in recs]
        return out

    def cut(self) -> list[PendingWindow]:
        """What the open window holds so far, as parts (`WindowBuilder.cut`): a bound on
        what a hard kill loses. Held odometry is scored first."""
        return self._drain() + self.windows.cut()

    def flush(self) -> list[PendingWindow]:
        """End of input: close the open window and the current summary period."""
        out = self._drain() + self.windows.flush()
        if self.summary is not None:
            out += [self._summary_window(r) for r in self.summary.flush()]
        return out

    @staticmethod
    def _summary_window(rec: tuple[int, str]) -> PendingWindow:
        return PendingWindow(SUMMARY_TOPIC, [rec], {"kind": "summary"})

    def run(self, stream: Iterable[tuple[str, int, str]]) -> Iterator[PendingWindow]:
        """Live mode over an iterable: yields windows as they close, then the flush."""
        for topic, stamp_ns, text in stream:
            yield from self.push(topic, stamp_ns, text)
        yield from self.flush()

    def replay(self, messages: list[tuple[str, int, str]]) -> list[PendingWindow]:
        """A recorded run at once: odometry parsed and scored in batch (same results as
        `run`, from a fresh detector), then the window logic in one pass."""
        odom_at = [i for i, m in enumerate(messages) if m[0] == self.odom_topic]
        odom = parse_odometry(messages[i][2] for i in odom_at)
        scores, flags, back = self.detector.score_windows(odom)
        out: list[PendingWindow] = []
        j = 0
        raw = odom.raw.tolist()
        for i, (topic, stamp_ns, text) in enumerate(messages):
            if j < len(odom_at) and odom_at[j] == i:
                out += self._odom(stamp_ns, text, raw[j], float(scores[j]), bool(flags[j]), int(back[j]))
                j += 1
            else:
                out += self.windows.push(topic, stamp_ns, text)
        return out + self.flush()


def collect(source, out_dir: str | Path, *, features: dict | str | None = "default",
            labels=None) -> dict:  # fmt: skip
    """Write a run's feature vectors as a labelled dataset (as in the paper): one `.npy`
    per vector under `nominal/` or `anomalous/`, and `dataset.json` with the feature
    config. Vectors that depend on an event but are not inside it are skipped."""
    feature_set = make_features(features)
    odom = _as_odom(source)
    X, valid = feature_set.batch(odom)
    inside, touched = event_masks(feature_set, odom.stamp_ns, labels)
    out = Path(out_dir)
    meta_path = out / "dataset.json"
    if meta_path.exists():
        meta = json.loads(meta_path.read_text())
        if meta.get("feature_config") != feature_set.get_config():
            raise InvalidInputError(f"{meta_path} holds vectors of other features: {meta}.")
    else:
        meta = {"feature_config": feature_set.get_config(), "nominal": 0, "anomalous": 0}
    for kind, mask in (("nominal", valid & ~touched), ("anomalous", valid & inside)):
        (out / kind).mkdir(parents=True, exist_ok=True)
        for i in np.nonzero(mask)[0]:
            np.save(out / kind / f"{meta[kind]:08d}_{odom.stamp_ns[i]}.npy", X[i], allow_pickle=False)
            meta[kind] += 1
    meta_path.write_text(json.dumps(meta, indent=1))
    return meta


def load_dataset(path: str | Path) -> tuple[dict, np.ndarray, np.ndarray]:
    """(feature_config, nominal vectors, anomalous vectors) of a collected dataset."""
    path = Path(path)
    try:
        meta = json.loads((path / "dataset.json").read_text())
    except (OSError, ValueError) as err:
        raise InvalidInputError(f"{path} is not a collected dataset: {err}.") from err
    dim = make_features(meta["feature_config"]).dim
    arrays = []
    for kind in ("nominal", "anomalous"):
        files = sorted((path / kind).glob("*.npy"))
        arrays.append(np.array([np.load(f, allow_pickle=False) for f in files]).reshape(-1, dim))
    return meta["feature_config"], arrays[0], arrays[1]
