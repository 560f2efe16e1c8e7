"""Where a slow feature's evidence starts (classifier/evidence.py, issue 15 seventh pass):
the whole-run and the live computation agree, and a window reaches back to the start of
the long columns' evidence, not their whole span."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.classifier import Detector, SmartLogger, train, window_spans
from cclogfs.classifier.evidence import EvidenceHistory, evidence_back
from cclogfs.classifier.features import NS
from cclogfs.classifier.testing import inject, odom_texts

MS = 1_000_000

# A message: (stamp step in ms, valid, value of column 0, value of column 1).
message = st.tuples(st.sampled_from([100, 100, 100, 0, 30, 1200, -50]), st.booleans(),
                    st.sampled_from([0.0, 0.0, 1.0, 2.0, float("nan")]), st.sampled_from([0.0, 0.5]))  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(steps=st.lists(message, max_size=1500), chunks=st.lists(st.integers(1, 70), min_size=1),
       margin=st.sampled_from([0, 200 * MS]))  # fmt: skip
def test_live_evidence_equals_whole_run(steps, chunks, margin):
    """Vectors appended one by one and taken a chunk at a time (every other row flagged)
    give the whole run's numbers."""
    check_live_equals_whole_run(steps, chunks, margin)


def test_live_evidence_equals_whole_run_after_dropping_old_rows():
    rng = np.random.default_rng(7)
    steps = [(int(rng.choice([100, 100, 0, 30, 1200, -50])), bool(rng.random() < 0.9),
              float(rng.choice([0.0, 0.0, 1.0, np.nan])), float(rng.choice([0.0, 0.5]))) for _ in range(5000)]  # fmt: skip
    check_live_equals_whole_run(steps, [64, 1, 17], 200 * MS, dropped=True)


def check_live_equals_whole_run(steps, chunks, margin, dropped=False):
    spans = (1000 * MS, 400 * MS)
    t, V, valid = [], [], []
    now = 5 * NS
    for step, ok, a, b in steps:
        now += step * MS
        t.append(now)
        V.append((a, b))
        valid.append(ok)
    t, V, valid = np.array(t, dtype=np.int64), np.array(V).reshape(-1, 2), np.array(valid, dtype=bool)
    want = evidence_back(t, V, valid, spans, margin)[valid]
    assert (want <= np.array(spans)).all()
    assert (want[np.nan_to_num(V[valid]) > 0] >= margin).all()
    live = EvidenceHistory((0, 1), spans, margin)
    for k in np.nonzero(valid)[0]:
        live.append(int(t[k]), V[k])
    got, done, c = [], 0, 0
    while done < len(want):
        n = min(chunks[c % len(chunks)], len(want) - done)
        flagged = np.arange(c % 2, n, 2)
        got.append((done + flagged, live.take(n, flagged)))
        done, c = done + n, c + 1
    for rows, backs in got:
        assert backs.tolist() == want[rows].tolist()
    assert not dropped or (len(live.stamps) < 256 and sum(map(len, live.runs)) < len(want) // 20)


def test_a_reversal_reaches_back_to_its_first_flip_not_8_s():
    """A column that is 0 until 1.5 s ago reaches back 1.5 s plus the margin; one nonzero
    for 20 s reaches back its whole span."""
    t = np.arange(0, 30 * NS, 100 * MS)
    V = np.zeros((len(t), 1))
    V[-15:, 0] = 1.0
    back = evidence_back(t, V, np.ones(len(t), bool), (8 * NS,), 200 * MS)
    assert back[-1, 0] == 1400 * MS + 200 * MS
    V[:, 0] = 1.0
    assert evidence_back(t, V, np.ones(len(t), bool), (8 * NS,), 0)[-1, 0] == 8 * NS


def test_live_push_many_and_replay_give_the_same_windows(halves):
    """The TurtleBot's second half: nav2 spins in place and backs up (long columns), and
    an injected oscillation. Live (one message at a time), a list at a time (held and
    scored in batches) and replay (whole run) give the same windows, and the long columns'
    lookbacks are their evidence, shorter than their spans."""
    model = train([halves[0]])
    test = halves[1]
    run, _ = inject(test, "oscillate", int(test.stamp_ns[0]) + 25 * NS, 4.0)
    messages = [("/odom", int(s), x) for s, x in zip(run.stamp_ns, odom_texts(run))]
    det = Detector(model)
    _, flags, back = det.score_windows(run)
    long_spans = det.spans_ns[list(det.counted)]
    assert flags.any() and 0 < back[flags].max() < long_spans.max()
    want = SmartLogger(Detector(model), summary_period_s=None, before_s=1, after_s=0.5).replay(messages)
    live = SmartLogger(Detector(model), summary_period_s=None, before_s=1, after_s=0.5)
    got = [w for m in messages for w in live.push(*m)] + live.flush()
    many = SmartLogger(Detector(model), summary_period_s=None, before_s=1, after_s=0.5, batch=16)
    got_many = many.push_many(messages) + many.flush()
    spans = window_spans(want)
    assert spans and window_spans(got) == spans and window_spans(got_many) == spans


def test_lookback_takes_the_earliest_long_evidence_when_a_long_column_stands_out(halves):
    """A vector whose yaw reversals stand out reaches back as far as the earliest of the long
    columns' evidence (a slow anomaly's start shows in the one that began first), at most
    the yaw reversals' span; one where
    only a short maximum stands out reaches back that maximum's span, whatever the backs."""
    det = Detector(train([halves[0]]))
    longs = list(det.counted)
    base = np.zeros(det.features.dim)
    slow, quick = base.copy(), base.copy()
    slow[9] = 50.0  # yaw reversals
    quick[1] = 50.0  # accel_max
    backs = np.zeros((2, len(longs)), dtype=np.int64)
    backs[:, longs.index(10)] = 3 * NS  # direction reversals began 3 s ago
    backs[:, longs.index(9)] = 1 * NS
    got = det.lookback_ns(np.array([slow, quick]), backs)
    assert got.tolist() == [3 * NS, int(det.spans_ns[1])]
    backs[:, longs.index(10)] = 6 * NS  # but never beyond the standing-out column's span
    assert det.lookback_ns(np.array([slow]), backs[:1])[0] == det.spans_ns[9] == 4 * NS
    assert det.lookback_ns(np.array([slow]))[0] == det.spans_ns[9]  # without backs: the span
