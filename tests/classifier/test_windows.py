import json

import pytest

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


def test_out_of_order_other_topic_is_taken_by_its_window():
    b = WindowBuilder(before=1, after=1, topics=["/a"])
    out = []
    for topic, stamp, flag in [("/odom", 100, True), ("/odom", 110, False), ("/a", 200, False),
                               ("/a", 105, False), ("/odom", 120, False), ("/odom", 130, False),
                               ("/odom", 300, False), ("/odom", 310, True)]:  # fmt: skip
        out += b.push(topic, stamp, f"{topic}{stamp}", anomalous=flag)
    out += b.flush()
    spans = [(w.start_ns, w.end_ns) for w in out if w.topic == "/odom"]
    kept = [(s, w) for w in out if w.topic == "/a" for s, _ in w.messages]
    assert spans == [(100, 110), (300, 310)]
    assert [s for s, _ in kept] == [105]
    assert spans[0][0] <= kept[0][0] <= spans[0][1]


def test_ring_is_bounded_by_count_when_stamps_freeze():
    b = WindowBuilder(before_s=8, after_s=8)  # default max_ring
    for _ in range(200_000):
        b.push("/odom", 1000 * MS, "odom")
    assert len(b.ring) <= b.max_ring + 1 <= 100_001


def test_held_window_with_frozen_stamps_closes_at_the_ring_cap():
    b = WindowBuilder(before_s=8, after_s=1, max_ring=500)
    b.push("/odom", 0, "a", anomalous=True)
    b.push("/odom", 2000 * MS, "b")  # after_s has passed: the window is held
    out = []
    for i in range(5000):
        out += b.push("/odom", 2000 * MS, f"c{i}")
        assert len(b.ring) <= 501
    assert [len(w.messages) for w in out if w.topic == "/odom"] == [2]


def test_clock_reset_is_a_gap():
    b = WindowBuilder(before_s=8, after_s=8)
    out = []
    for i in range(100):
        out += b.push("/odom", (5000 + i) * 1000 * MS, f"old{i}", anomalous=(i == 90))
    for i in range(100):  # the clock restarts near zero
        out += b.push("/odom", i * 1000 * MS, f"new{i}")
        assert len(b.ring) <= 9
    (w,) = [w for w in out if w.topic == "/odom"]
    assert {t for _, t in w.messages} == {f"old{i}" for i in range(82, 99)}
    assert b.window is None


def test_after_zero_logs_only_the_anomaly():
    flags = [False] * 20
    flags[5] = True
    assert odom_indices(feed(WindowBuilder(before=0, after=0), flags)) == [[5]]
    assert odom_indices(feed(WindowBuilder(before=2, after=0), flags)) == [[3, 4, 5]]


def test_latched_topic_keeps_the_newest_texts():
    b = WindowBuilder(before=1, after=1)
    for i in range(70):
        b.push("/tf_static", i, f"static{i}")
    out = b.push("/odom", 100, "odom", anomalous=True) + b.flush()
    (latched,) = [w for w in out if w.topic == "/tf_static"]
    assert [t for _, t in latched.messages] == [f"static{i}" for i in range(70 - 64, 70)]
    assert latched.meta["latched_dropped"] == 6


def test_anomalies_within_the_merge_gap_join_one_window():
    """merge_s: a second anomaly whose context comes within merge_s of the closed window
    joins it, the gap logged; farther, it is a window of its own."""
    flags = [False] * 600
    flags[100] = flags[200] = flags[450] = True  # context 0.2 s, after 0.1 s
    args = dict(before_s=0.2, after_s=0.1, lookback_max_s=0.5, merge_s=0.9)
    first, second = odom_indices(feed(WindowBuilder(**args), flags))
    assert first == list(range(80, 211)) and second == list(range(430, 461))
    apart = odom_indices(feed(WindowBuilder(**(args | {"merge_s": 0.0})), flags))
    assert apart[0] == list(range(80, 111)) and len(apart) == 3


def test_hold_score_keeps_a_window_open_while_the_score_is_close():
    """Hysteresis: messages scoring above hold_score extend an open window like an
    anomaly; they open none."""
    b = WindowBuilder(before_s=0.0, after_s=0.05, hold_score=-0.5)
    out = []
    for i in range(100):
        score = 1.0 if i == 20 else (-0.2 if 20 < i < 40 or i == 70 else -2.0)
        out += b.push("/odom", i * 10 * MS, f"odom{i}", anomalous=score > 0, score=score)
    (w,) = odom_indices(out + b.flush())
    assert w == list(range(20, 45))


def test_a_later_flag_extends_the_window_back_with_other_topics():
    """A quick flag opens a window 0.1 s before its evidence; a slow one 0.5 s later whose
    evidence reaches 1 s back extends it back, trigger and other topics alike, and nothing
    is logged twice (issue 15, sixth pass: before, what the start left out was dropped)."""
    b = WindowBuilder(before_s=0.1, after_s=0.1, lookback_max_s=2.0, merge_s=0.0)
    out = []
    for i in range(300):  # odometry every 10 ms, /scan between
        out += b.push("/scan", i * 10 * MS + 5 * MS, f"scan{i}")
        flag, back = {150: (True, 50 * MS), 200: (True, 1000 * MS)}.get(i, (False, 0))
        out += b.push("/odom", i * 10 * MS, f"odom{i}", anomalous=flag, lookback_ns=back)
    out += b.flush()
    (odom,) = odom_indices(out)
    assert odom == list(range(90, 211))  # 2 s - 1 s - 0.1 s = 0.9 s, up to 0.1 s after
    scans = [int(t[4:]) for w in out if w.topic == "/scan" for _, t in w.messages]
    assert scans == list(range(90, 210))
    assert out[-1].meta["start_ns"] == 900 * MS


def test_a_part_that_goes_out_as_the_window_opens_names_its_flag():
    """At 2 kHz, a slow flag (8 s of lookback) opens a window with 9 s of context: 18,000
    messages, more than a part holds, so a part goes out as the window opens. Its meta
    named no flag and a peak score of -inf, which the store refuses as JSON: the recording
    stopped with "meta is not JSON-serializable" and the window was not stored."""
    b = WindowBuilder(before_s=1.0, after_s=0.5, lookback_max_s=8.0, merge_s=4.5, hold_score=-0.3)
    out = []
    for k in range(30_000):  # 0.5 ms apart; the flag at 10 s
        flag = k == 20_000
        out += b.push("/odom", k * MS // 2, str(k), anomalous=flag, score=2.5 if flag else -1.0,
                      lookback_ns=8000 * MS if flag else 0)  # fmt: skip
    out += b.flush()
    assert [len(w.messages) for w in out] == [10_000, 9_001]  # 1 s .. 10.5 s
    for w in out:
        assert w.meta["peak_score"] == 2.5 and w.meta["n_triggers"] == 1 and w.meta["triggers"] == [10_000 * MS]
        json.dumps(w.meta, allow_nan=False)  # as the store encodes it: raises for -inf
