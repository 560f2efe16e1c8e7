import json

import pytest

from cclogfs.classifier.summary import SummaryBuilder
from cclogfs.classifier.windows import WindowBuilder
from cclogfs.errors import InvalidInputError

MS = 1_000_000


def feed(builder, flags, *, other_every=0, latched_at=None):
    """Odometry i at i*10 ms, anomalous where flags[i]; /scan every `other_every` messages."""
    out = []
    for i, flag in enumerate(flags):
        if latched_at == i:
            out += builder.push("/tf_static", i * 10 * MS, "static")
        if other_every and i % other_every == 0:
            out += builder.push("/scan", i * 10 * MS + 5 * MS, f"scan{i}")
        out += builder.push("/odom", i * 10 * MS, f"odom{i}", anomalous=flag, score=float(i))
    return out + builder.flush()


def odom_indices(windows):
    return [[int(t[4:]) for _, t in w.messages] for w in windows if w.topic == "/odom"]


def test_window_has_context_and_after():
    flags = [False] * 100
    flags[50] = True
    (w,) = odom_indices(feed(WindowBuilder(before=10, after=5), flags))
    assert w == list(range(40, 56))


def test_overlapping_windows_merge_and_distant_ones_do_not():
    flags = [False] * 200
    flags[50] = flags[65] = True  # context of 65 (55..64) overlaps window 40..55
    flags[150] = True
    got = odom_indices(feed(WindowBuilder(before=10, after=5), flags))
    assert got == [list(range(40, 71)), list(range(140, 156))]
    all_msgs = [i for w in got for i in w]
    assert len(all_msgs) == len(set(all_msgs))


def test_touching_windows_merge():
    flags = [False] * 100
    flags[20] = flags[36] = True  # window 1 ends at 25; context of 36 starts at 26
    got = odom_indices(feed(WindowBuilder(before=10, after=5), flags))
    assert got == [list(range(10, 42))]


def test_long_window_emitted_in_parts_sharing_id():
    flags = [True] * 95 + [False] * 20
    ws = [w for w in feed(WindowBuilder(before=3, after=3, max_part=20), flags) if w.topic == "/odom"]
    assert [len(w.messages) for w in ws] == [20] * 4 + [18]
    assert len({w.meta["window_id"] for w in ws}) == 1
    assert [w.meta["part"] for w in ws] == list(range(5))
    assert [w.meta["final"] for w in ws] == [False] * 4 + [True]
    assert ws[-1].meta["n_triggers"] == 95 and ws[-1].meta["peak_score"] == 94.0


def test_other_topics_cover_window_span_and_latched_are_added():
    flags = [False] * 100
    flags[50] = True
    ws = feed(WindowBuilder(before=10, after=5, model_id="m1"), flags, other_every=2, latched_at=3)
    by_topic = {w.topic: w for w in ws}
    assert set(by_topic) == {"/odom", "/scan", "/tf_static"}
    odom, scan = by_topic["/odom"], by_topic["/scan"]
    assert all(odom.start_ns <= s <= odom.end_ns for s, _ in scan.messages)
    assert [t for _, t in scan.messages] == [f"scan{i}" for i in range(40, 55, 2)]
    assert by_topic["/tf_static"].messages == [(30 * MS, "static")]
    assert odom.meta["model_id"] == "m1" and odom.meta["triggers"] == [500 * MS]


def test_durations_instead_of_counts():
    flags = [False] * 300
    flags[100] = True
    (w,) = odom_indices(feed(WindowBuilder(before_s=0.2, after_s=0.3), flags))
    assert w == list(range(80, 131))


def test_unlisted_topics_ignored_and_bad_sizes_rejected():
    flags = [False] * 30
    flags[10] = True
    ws = feed(WindowBuilder(before=2, after=2, topics=["/odom"]), flags, other_every=1)
    assert {w.topic for w in ws} == {"/odom", "/tf_static"} - {"/tf_static"}
    with pytest.raises(InvalidInputError):
        WindowBuilder(before=-1)


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
