"""cclogfs.classifier.summary: per-period statistics of the odometry, one record a period."""

import json
import math
from functools import reduce
from operator import add

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.classifier import summary
from cclogfs.classifier.summary import SummaryBuilder

MS = 1_000_000


def test_summary_per_minute():
    sb = SummaryBuilder(period_s=60)
    recs = []
    for i in range(0, 1300):  # 130 s at 10 Hz, moving 0.5 m/s along x
        t = i * 100 * MS
        recs += sb.update(t, 0.05 * i, 0.0, 0.5, anomalous=(i == 700))
    recs += sb.flush()
    stats = [json.loads(t) for _, t in recs]
    assert [s["messages"] for s in stats] == [600, 600, 100]
    assert stats[0]["distance_m"] == pytest.approx(29.95)
    assert stats[1]["anomalies"] == 1 and stats[1]["peak_speed"] == 0.5
    assert stats[0]["moving_s"] == pytest.approx(59.9)


def test_nothing_seen_gives_no_record():
    assert SummaryBuilder(period_s=60).flush() == []


# A sample: (stamp step in ms, speed, step along x in m); steps past the 1 s gap, back and
# zero, NaN and infinite speeds and positions.
sample = st.tuples(st.sampled_from([100, 100, 100, 37, 0, -40, 1500, 9000]),
                   st.sampled_from([0.5, -0.7, 0.01, 2.3, math.nan, math.inf]),
                   st.sampled_from([0.05, 0.0, -0.013, math.nan]))  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(samples=st.lists(sample, max_size=150), size=st.integers(1, 70), held=st.sampled_from([3, 1024]),
       start=st.sampled_from([0, 1_732_000_000_123_456_789, -3_000_000_001]))  # fmt: skip
def test_update_many_is_update_of_each(samples, size, held, start):
    """Lists of `size` samples: the same records from the same samples, bit for bit, and
    the same state after (with at most `held` samples held). Stamps from 0 or a real
    clock's (numpy's int64 path, issue 14)."""
    stamps, rows, speeds, flags, t, x = [], [], [], [], start, 0.0
    for k, (step, speed, dx) in enumerate(samples):
        t, x = t + step * MS, x + dx
        stamps.append(t)
        rows.append((x, 0.5 * x, 0.0))
        speeds.append(speed)
        flags.append(k % 7 == 0)
    one, many = SummaryBuilder(period_s=10), SummaryBuilder(period_s=10)
    want = [(k, r) for k in range(len(stamps)) for r in one.update(stamps[k], rows[k][0], rows[k][1], speeds[k], flags[k])]
    got = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(summary, "MAX_HELD", held)
        for at in range(0, len(stamps), size):
            part = slice(at, at + size)
            got += [(at + k, r) for k, r in many.update_many(stamps[part], rows[part], speeds[part], flags[part])]
    assert got == want
    # `update` after update_many takes the held samples first
    assert many.update(t + 10_000 * MS, x, x, 1.0, False) == one.update(t + 10_000 * MS, x, x, 1.0, False)
    assert repr((many.stats, many.prev, list(many.recent), many.bucket, many.first_ns, many.last_ns)) == repr(
        (one.stats, one.prev, list(one.recent), one.bucket, one.first_ns, one.last_ns))
    assert many.flush() == one.flush()


def test_ordered_sum_adds_in_order():
    """`_ordered_sum` is `update`'s one-by-one sum, bit for bit: on these values numpy's
    pairwise `sum` gives other last bits, so a sum in another order fails here."""
    rng = np.random.default_rng(14)
    values = rng.random(1000) * 10.0 ** rng.integers(-6, 6, 1000)
    one_by_one = reduce(add, values.tolist(), 0.3)
    assert float(np.concatenate(((0.3,), values)).sum()) != one_by_one
    assert summary._ordered_sum(0.3, values) == one_by_one
    assert summary._ordered_sum(0.3, values[:0]) == 0.3
