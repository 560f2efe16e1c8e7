"""Where a slow feature's evidence starts (classifier/evidence.py, issue 15 seventh pass):
the whole-run and the live computation agree, and a window reaches back to the start of
the long columns' evidence, not their whole span."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.classifier import Detector, SmartLogger, parse_odometry, train, window_spans
from cclogfs.classifier.evidence import EvidenceTracker, evidence_back
from cclogfs.classifier.features import NS
from cclogfs.classifier.testing import inject, odom_texts, read_odometry

MS = 1_000_000

# A message: (stamp step in ms, valid, value of column 0, value of column 1).
message = st.tuples(st.sampled_from([100, 100, 100, 0, 30, 1200, -50]), st.booleans(),
                    st.sampled_from([0.0, 0.0, 1.0, 2.0, float("nan")]), st.sampled_from([0.0, 0.5]))  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(steps=st.lists(message, max_size=150), margin=st.sampled_from([0, 200 * MS]))
def test_live_evidence_equals_whole_run(steps, margin):
    spans = (1000 * MS, 400 * MS)
    t, V, valid = [], [], []
    now = 5 * NS
    for step, ok, a, b in steps:
        now += step * MS
        t.append(now)
        V.append((a, b))
        valid.append(ok)
    t, V, valid = np.array(t, dtype=np.int64), np.array(V).reshape(-1, 2), np.array(valid, dtype=bool)
    want = evidence_back(t, V, valid, spans, margin)
    live = EvidenceTracker((0, 1), spans, margin)
    for k in range(len(t)):
        if not valid[k]:
            live.stamp(int(t[k]))
            assert not want[k].any()
            continue
        got = live.push(int(t[k]), V[k])
        assert (want[k].tolist() == [0, 0]) if got is None else (list(got) == want[k].tolist())
        for c in range(2):  # never more than the span, nonzero only where the column is
            assert want[k, c] <= spans[c]
            if V[k, c] > 0:
                assert want[k, c] >= margin


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


@pytest.fixture(scope="module")
def halves():
    from conftest import shared_data_file

    odom = parse_odometry(read_odometry(shared_data_file("nav2_turtlebot.mcap")))
    t = odom.stamp_ns
    mid = t[0] + (t[-1] - t[0]) // 2
    return odom.take(t < mid), odom.take(t >= mid)


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
