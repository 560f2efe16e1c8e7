"""cclogfs.classifier.summary: per-period statistics of the odometry, one record a period."""

import json

import pytest

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
