"""cclogfs.upkeep.background: `Upkeep`, retention and aging run by the recorder while it records."""

from __future__ import annotations

import threading

import pytest

import cclogfs
from _odom import NS, odom, sealed_store
from cclogfs.errors import InvalidInputError
from cclogfs.pipeline import Logger
from cclogfs.store import check_store
from cclogfs.upkeep import Policy, Upkeep, parse_rule
from helpers import flip


@pytest.mark.parametrize(
    "kwargs, match",
    [({"budget": 0}, "positive number of bytes"), ({"policy": Policy([parse_rule("1e-3")])}, "needs an age"),
     ({"policy": Policy([parse_rule("1e-3")]), "older_than_ns": -1}, "needs an age"), ({}, "budget, an aging policy")],
)  # fmt: skip
def test_an_incomplete_upkeep_is_refused(kwargs, match):
    with pytest.raises(InvalidInputError, match=match):
        Upkeep(**kwargs)


def test_segments_are_an_eighth_of_the_budget_within_limits():
    assert Upkeep(budget=8 << 20).store_options() == {"segment_bytes": 1 << 20}
    assert Upkeep(budget=1 << 10).store_options() == {"segment_bytes": 4096}
    assert Upkeep(budget=48 << 10).store_options() == {"segment_bytes": 6 << 10}
    assert Upkeep(budget=1 << 40).store_options() == {"segment_bytes": 64 << 20}
    assert Upkeep(policy=Policy([parse_rule("1e-3")]), older_than_ns=0).store_options() == {}


def test_logger_sizes_its_segments_for_its_budget(tmp_path):
    with Logger(str(tmp_path / "s"), chunk=100, upkeep=Upkeep(budget=256 << 10)) as log:
        for i in range(40_000):
            log("/odom", i * NS // 20, odom(i))
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        assert s.data_bytes() <= 256 << 10 and s.dropped()["segments"] >= 1


def test_logger_with_background_aging_stops_cleanly_and_keeps_every_window(tmp_path):
    upkeep = Upkeep(budget=1 << 20, policy=Policy([parse_rule("1e-3")]), older_than_ns=60 * NS)
    with Logger(str(tmp_path / "s"), chunk=50, upkeep=upkeep) as log:
        for i in range(20_000):
            log("/odom", i * NS // 20, odom(i))
    assert upkeep.errors == []
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        windows = list(s.query("/odom"))
        assert windows[-1].end_ns == 19_999 * NS // 20
        assert upkeep.aged_windows > 0 and any(w.aged is not None for w in windows)
        assert [w.seq for w in windows] == list(range(windows[0].seq, windows[0].seq + len(windows)))
    report = check_store(str(tmp_path / "s"), deep=True)
    assert not report.errors and not report.findings  # no leftover from a stopped rewrite


def test_background_aging_goes_past_a_segment_holding_a_stream_that_stopped(tmp_path):
    store = sealed_store(tmp_path / "s")
    upkeep = Upkeep(policy=Policy([parse_rule("1e-3")]), older_than_ns=20 * NS, streams=["/odom"])
    upkeep.after_put(store)
    upkeep.close(finish=True)
    aged = [w.seq for w in store.query("/odom") if w.aged is not None]
    # /odom windows ending over 20 s before the newest sealed one (74.9 s): 0-9, all of them
    assert aged == list(range(1, 11)) and upkeep.errors == []
    store.close()


def test_finishing_after_an_error_returns_and_later_segments_still_age(tmp_path):
    store = sealed_store(tmp_path / "s")
    store.close()
    seg = tmp_path / "s" / "00000000000000000000.seg"
    flip(seg, -5, 0xFF)  # damage the oldest segment
    store = cclogfs.open_store(tmp_path / "s", segment_records=4, sync_every_ms=None)
    upkeep = Upkeep(policy=Policy([parse_rule("1e-3")]), older_than_ns=20 * NS)
    upkeep.after_put(store)
    closer = threading.Thread(target=upkeep.close, kwargs={"finish": True})
    closer.start()
    closer.join(30)
    assert not closer.is_alive(), "close(finish=True) hung after an error"
    assert len(upkeep.errors) == 1 and "CorruptionError" in upkeep.errors[0]
    assert any(w.aged is not None for w in store.query("/odom") if w.seq >= 4)
    store.close()


def test_aging_buys_history_under_the_same_budget(tmp_path, shared_data):
    # Issue 16 item 9: recording with aging kept exactly what the budget alone kept (the
    # same 4,560 messages of this log), since retention ran before aging saved anything.
    from bench.aging_history import kept_history

    log = shared_data("long/slamfail_long_passage.mcap")
    plain = kept_history(log, tmp_path / "plain", "192KiB", [])
    aged = kept_history(log, tmp_path / "aged", "192KiB", ["--age-older-than", "2min", "--age-error", "1e-3"])
    assert plain["bytes"] <= 192 << 10 and aged["bytes"] <= 192 << 10
    assert aged["aged_windows"] > 0 and aged["first_ns"] < plain["first_ns"]
    assert aged["messages"] > 1.25 * plain["messages"], (plain, aged)
