"""cclogfs.classifier.evaluate: the paper's tables, per message and per labelled event."""

import numpy as np
import pytest

from cclogfs.classifier.evaluate import (detection_delays, event_table, format_event_table, format_message_table,
                                         message_table, window_spans)  # fmt: skip
from cclogfs.classifier.features import NS
from cclogfs.classifier.windows import PendingWindow


def test_detection_delay_and_nominal_time():
    t = np.arange(0, 100 * NS, NS // 10)
    flags = np.zeros(len(t), bool)
    flags[205:215] = True  # 0.5 s after the first event starts
    labels = {"events": [{"start_ns": 20 * NS, "end_ns": 22 * NS}, {"start_ns": 60 * NS, "end_ns": 61 * NS}]}
    d = detection_delays(t, flags, labels)
    assert d[0] == pytest.approx(0.5) and np.isnan(d[1])
    table = event_table(t, [(int(19 * NS), int(23 * NS)), (int(80 * NS), int(81 * NS))], labels, flags)
    assert table["recalled"] == 1 and table["false_windows"] == 1 and table["detected"] == 1
    assert table["nominal_minutes"] == pytest.approx((t[-1] - t[0]) / 60e9 - 3 / 60)
    assert table["false_per_10min"] == pytest.approx(10 / table["nominal_minutes"])
    assert "median 0.50 s" in format_event_table(table)
    assert event_table(t, [], labels)["delay_median_s"] is None


def test_message_table_counts_each_message_once():
    t = np.arange(10) * NS
    flags = np.array([0, 1, 1, 0, 0, 0, 1, 0, 0, 0], bool)
    labels = {"events": [{"start_ns": 1 * NS, "end_ns": 3 * NS}]}  # messages 1, 2, 3
    table = message_table(t, flags, labels)
    assert {k: table[k] for k in ("total", "tp", "fp", "fn", "tn")} == {"total": 10, "tp": 2, "fp": 1, "fn": 1, "tn": 6}
    assert table["precision"] == pytest.approx(2 / 3) and table["recall"] == pytest.approx(2 / 3)
    assert "Precision           66.7%" in format_message_table(table)
    none = message_table(t, np.zeros(10, bool), labels)
    assert np.isnan(none["precision"]) and none["recall"] == 0.0  # nothing flagged: no precision to speak of


def test_window_spans_join_parts_of_one_window_and_skip_other_topics():
    windows = [
        PendingWindow("/odom", [(10, "a"), (20, "b")], {"window_id": "w1"}),
        PendingWindow("/odom", [(21, "c"), (30, "d")], {"window_id": "w1"}),  # a second part
        PendingWindow("/odom", [(5, "e")]),
        PendingWindow("/scan", [(0, "f"), (100, "g")]),
        PendingWindow("/odom", []),
    ]
    assert window_spans(windows) == [(5, 5), (10, 30)]
    assert window_spans(windows, "/scan") == [(0, 100)]
