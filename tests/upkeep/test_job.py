"""Compaction and aging end to end: `cclogfs.upkeep` and `cclog compact`."""

from __future__ import annotations

import json
import os
import re
import threading
import time

import pytest

import cclogfs
from cclogfs.upkeep import Policy, parse_rule
from cclogfs.cli import main
from cclogfs.upkeep import compact
from cclogfs.runs import list_runs
from cclogfs.store import check_store
from _odom import NS, odom, sealed_store


def build(path, windows=12, per=50, **kw):
    """`windows` windows of /odom at 10 Hz (one per 5 s), one summary message each."""
    with cclogfs.open_store(path, create=True, **kw) as store:
        for w in range(windows):
            store.put_window("/odom", [(i * NS // 10, odom(i)) for i in range(w * per, (w + 1) * per)])
            store.put_window("/cclog/summary", [(w * 5 * NS, json.dumps({"distance_m": 1.23456789}))])


def floats(value):
    if isinstance(value, float):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from floats(v)
    elif isinstance(value, list):
        for v in value:
            yield from floats(v)


def test_old_windows_age_within_bounds_and_new_ones_stay_exact(tmp_path):
    build(tmp_path / "s")  # never sealed: compaction must seal to reach old windows
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        before = {w.seq: list(w.messages()) for w in s.query("/odom")}
    with cclogfs.open_store(tmp_path / "s") as store:
        report = compact(store, policy=Policy([parse_rule("1e-3"), parse_rule("header.**=0")]),
                         older_than_ns=30 * NS)  # fmt: skip
    cutoff = 599 * NS // 10 - 30 * NS  # the newest /odom message is at 59.9 s
    assert report.aged["/odom"]["windows"] == 5  # windows 0-4 end before it, at 4.9 ... 24.9 s
    assert "/cclog/summary" not in report.aged  # excluded by default
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        for w in s.query("/odom"):
            msgs = list(w.messages())
            if w.end_ns < cutoff:
                assert w.flags & 1 and w.aged[-1]["rules"] == [["**", 0.001], ["header.**", 0.0]]
                assert w.aged[-1]["messages_before"] == 50
                for (s0, t0), (s1, t1) in zip(before[w.seq], msgs, strict=True):
                    assert s0 == s1
                    a, b = json.loads(t0), json.loads(t1)
                    assert a["header"] == b["header"] and a["pose"]["n"] == b["pose"]["n"]
                    for u, v in zip(floats(a), floats(b), strict=True):
                        assert abs(u - v) <= 1e-3 * (1 + 1e-12)
            else:
                assert w.aged is None and msgs == before[w.seq]
        for w in s.query("/cclog/summary"):
            assert w.aged is None
    assert not check_store(str(tmp_path / "s"), deep=True).errors


def test_same_policy_twice_rewrites_nothing_and_a_new_one_adds_a_pass(tmp_path):
    build(tmp_path / "s", segment_records=4)
    policy = Policy([parse_rule("1e-3")])
    with cclogfs.open_store(tmp_path / "s") as store:
        first = compact(store, policy=policy)
        size = store.disk_bytes()
        again = compact(store, policy=policy)
        assert again.aged == {} and store.disk_bytes() == size
        thinner = compact(store, policy=Policy([parse_rule("1e-2")], max_rate_hz=2))
    assert first.aged["/odom"]["windows"] == 12
    assert thinner.aged["/odom"]["messages_after"] < thinner.aged["/odom"]["messages_before"]
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        w = next(iter(s.query("/odom")))
        assert [p["rules"] for p in w.aged] == [[["**", 0.001]], [["**", 0.01]]]
        assert len(list(w.messages())) == 10  # 2 Hz over 4.9 s: 0, 0.5 .. 4.0 s and the last (4.9 s; not 4.5)
        assert (w.start_ns, w.end_ns) == (0, 49 * NS // 10)


def test_budget_drops_oldest_segments_and_says_when_it_cannot(tmp_path):
    build(tmp_path / "s", segment_records=4)
    with cclogfs.open_store(tmp_path / "s") as store:
        total = store.data_bytes()
        report = compact(store, budget=total // 2)
        assert store.data_bytes() <= total // 2 and not report.over_budget
        assert report.segments_dropped >= 1
        first_left = min(w.start_ns for w in store.query("/odom"))
        assert first_left > 0 and report.dropped["/odom"]["start_ns"] == 0
        impossible = compact(store, budget=1)
        assert impossible.over_budget
        assert store.dropped()["segments"] == report.segments_dropped + impossible.segments_dropped


def test_cli_ages_reports_and_exits_by_outcome(tmp_path, capsys):
    build(tmp_path / "s", segment_records=4)
    path = str(tmp_path / "s")
    assert main(["compact", path, "--older-than", "30s", "--error", "1e-3", "--stream", "/odom"]) == 0
    out = capsys.readouterr().out
    assert "windows ending over 30s before their stream's last" in out and "/odom" in out
    assert main(["compact", path, "--older-than", "30s", "--error", "1e-3", "--stream", "/odom"]) == 0
    assert "nothing to age" in capsys.readouterr().out
    # A budget smaller than a segment is refused (it dropped every sealed segment, l-left8).
    assert main(["compact", path, "--budget", "1B", "--json"]) == 1
    assert "give --budget" in capsys.readouterr().err
    assert main(["info", path]) == 0
    assert "retention dropped" not in capsys.readouterr().out
    build(tmp_path / "one")  # never sealed: only the segment being written, which retention keeps
    assert main(["compact", str(tmp_path / "one"), "--budget", "1B", "--json"]) == 3
    assert json.loads(capsys.readouterr().out)["over_budget"] is True


def test_compact_refuses_a_budget_under_which_every_sealed_segment_goes(tmp_path, capsys):
    """A budget smaller than a segment dropped every sealed segment and said "budget met",
    exit 0, when the segment being written fitted (nav2_turtlebot recorded with --budget
    512KiB: 7,200 of 8,197 messages gone at --budget 40KiB). It is refused before anything
    is dropped, naming the smallest budget that keeps the newest sealed segment, which works."""
    build(tmp_path / "s", segment_records=4)
    path = str(tmp_path / "s")
    with cclogfs.open_store(path, readonly=True) as s:
        sealed = s.sealed_segments()
        before = s.data_bytes()
    assert len(sealed) > 2
    capsys.readouterr()
    for dry in ([], ["--dry-run"]):
        assert main(["compact", path, "--budget", "2KiB", *dry]) == 1
        err = capsys.readouterr().err
        m = re.search(r"--budget 2KiB is too small: .* retention would drop all of the store's sealed segments "
                      r"\((\d+), ([\d,]+) messages\); give --budget (\d+)KiB or more\.", err)
        assert m is not None and "Traceback" not in err, err
    with cclogfs.open_store(path, readonly=True) as s:
        assert s.data_bytes() == before and len(s.sealed_segments()) == len(sealed)  # nothing dropped
        assert int(m.group(1)) == len(sealed) and int(m.group(2).replace(",", "")) == sum(
            st["messages"] for seg in sealed for name, st in seg.streams.items() if name != "/cclog/runs")
    assert main(["compact", path, "--budget", f"{m.group(3)}KiB"]) == 0
    assert "budget" in capsys.readouterr().out
    with cclogfs.open_store(path, readonly=True) as s:
        assert [seg.first_seq for seg in s.sealed_segments()] == [sealed[-1].first_seq]  # the newest kept


@pytest.mark.parametrize(
    "args, match",
    [([], "Nothing to do"), (["--error", "x=y"], "PATTERN=BOUND"), (["--budget", "lots"], "Size 'lots'"),
     (["--older-than", "3 months", "--error", "1e-3"], "Duration"),
     (["--older-than", "3d"], "give --error or --max-rate"),
     # A rule matching no field (misspelt, or with msg. in front) aged that field by the
     # general bound, for good, exit 0 (found by attack); dry runs say so too.
     (["--error", "1e-3", "--error", "pose.xx=0"], "--error 'pose.xx=0' matches no number field"),
     (["--error", "1e-3", "--error", "msg.pose.x=0", "--dry-run"], "'msg.pose.x=0' matches no number field"),
     # A misspelt --stream said "nothing to age (no window old enough...)", exit 0.
     (["--error", "1e-3", "--stream", "/odom", "--stream", "/odmo"], "--stream /odmo matches no stream of")],
)  # fmt: skip
def test_cli_refuses_bad_arguments_and_leaves_the_store_alone(tmp_path, capsys, args, match):
    build(tmp_path / "s", windows=3)
    files = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    assert main(["compact", str(tmp_path / "s"), *args]) == 1
    assert match in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()} == files


def test_real_log_ages_within_bound_and_shrinks(tmp_path, shared_data):
    from rosbags.highlevel import AnyReader

    from cclogfs.jsontext.ros import MessageConverter, message_stamp_ns

    to_json = MessageConverter().to_json
    with AnyReader([shared_data("nav2_turtlebot.mcap")]) as reader, \
            cclogfs.open_store(tmp_path / "s", create=True) as store:  # fmt: skip
        per_topic: dict[str, list] = {}
        for con, logtime, raw in reader.messages():
            msg = reader.deserialize(raw, con.msgtype)
            per_topic.setdefault(con.topic, []).append((message_stamp_ns(msg) or logtime, to_json(msg)))
        for topic, msgs in per_topic.items():
            for i in range(0, len(msgs), 200):
                store.put_window(topic, msgs[i : i + 200])
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        exact = {w.seq: list(w.messages()) for w in s.query()}
    with cclogfs.open_store(tmp_path / "s") as store:
        size = store.data_bytes()
        compact(store, policy=Policy([parse_rule("1e-3")]))
        assert store.data_bytes() < 0.7 * size
    with cclogfs.open_store(tmp_path / "s", readonly=True) as s:
        for w in s.query():
            for (_, t0), (_, t1) in zip(exact[w.seq], w.messages(), strict=True):
                for u, v in zip(floats(json.loads(t0)), floats(json.loads(t1)), strict=True):
                    assert abs(u - v) <= 1e-3 * (1 + 1e-12)
    assert not check_store(str(tmp_path / "s"), deep=True).errors


def jsonl(path, n, hz=20):
    with open(path, "w") as f:
        for i in range(n):
            f.write(json.dumps({"topic": "/odom", "stamp_ns": i * NS // hz, "msg": json.loads(odom(i))}) + "\n")


def test_recorder_keeps_to_its_budget_as_it_goes(tmp_path, capsys):
    jsonl(tmp_path / "run.jsonl", 40_000)  # 2000 s at 20 Hz: 651 KiB stored
    store = str(tmp_path / "s")
    assert main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--budget", "256KiB", "--chunk", "100"]) == 0
    err = capsys.readouterr().err
    assert "budget 256.0 KiB met" in err, err
    with cclogfs.open_store(store, readonly=True) as s:
        assert s.data_bytes() <= 256 << 10
        assert s.dropped()["segments"] >= 1
        windows = list(s.query("/odom"))
        # What is left is the newest stretch, gapless, every window exact (the log's seqs
        # hold the run records retention carried too: /cclog/runs).
        assert windows[-1].end_ns == 39_999 * NS // 20
        seqs = sorted(w.seq for w in s.query())
        assert seqs == list(range(s.first_seq, s.first_seq + len(seqs)))
        assert [w.seq for w in windows] == [q for q in seqs if q >= windows[0].seq and q not in
                                            {w.seq for w in s.query("/cclog/runs")}]  # fmt: skip
        assert [stamp for w in windows for stamp, _t in w.messages()] == \
            list(range(windows[0].start_ns, 40_000 * NS // 20, NS // 20))
        assert all(w.aged is None for w in windows)
    assert not check_store(store, deep=True).errors


def test_recorder_summary_counts_what_retention_left_not_what_it_stored(tmp_path, capsys):
    """Found by attack: `record --budget` said "40,000 kept" when retention had dropped most of
    them to stay within the budget. Now it says what the store holds of the run, what
    retention dropped of it, and what it dropped of earlier runs."""
    import re

    jsonl(tmp_path / "run.jsonl", 40_000)
    jsonl(tmp_path / "run2.jsonl", 20_000, hz=40)  # other content, so not refused as recorded already
    store = str(tmp_path / "s")

    def held():
        with cclogfs.open_store(store, readonly=True) as s:
            return s.streams()["/odom"]["messages"]

    assert main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--budget", "256KiB", "--chunk", "100"]) == 0
    err = capsys.readouterr().err
    kept = held()
    assert 0 < kept < 40_000
    assert (f"40,000 messages in, {kept:,} kept (40,000 stored, then retention DROPPED the oldest {40_000 - kept:,} "
            "to stay within --budget)") in err, err  # fmt: skip
    assert "of earlier runs" not in err
    assert main(["record", str(tmp_path / "run2.jsonl"), "--store", store, "--budget", "256KiB", "--chunk", "100"]) == 0
    err = capsys.readouterr().err
    m = re.search(r"20,000 messages in, ([\d,]+) kept \(20,000 stored, then retention DROPPED the oldest ([\d,]+) ", err)
    assert m is not None, err
    mine, dropped = (int(g.replace(",", "")) for g in m.groups())
    assert mine + dropped == 20_000 and held() == mine  # every earlier message gone: this run alone fills the budget
    assert f"{store}: retention also dropped {kept:,} messages of earlier runs to stay within --budget" in err


def test_recorder_refuses_a_budget_too_small_for_any_segment(tmp_path, capsys):
    """A budget under 8 of the smallest segments (4 KiB) cannot keep any of a run: it was
    taken, retention dropped every segment, and the run ended "budget met" (found by
    attack); it is refused before anything is written, naming the smallest that works."""
    jsonl(tmp_path / "run.jsonl", 4_050)
    store = str(tmp_path / "s")
    assert main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--budget", "4KiB", "--chunk", "100",
                 "--codec", "none"]) == 1
    err = capsys.readouterr().err
    assert "--budget 4KiB is too small" in err and "give --budget 32KiB or more" in err, err
    assert not os.path.exists(store)
    assert main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--budget", "32KiB", "--chunk", "100",
                 "--codec", "none"]) == 0
    with cclogfs.open_store(store, readonly=True) as s:
        assert s.data_bytes() <= 32 << 10 and sum(len(list(w.messages())) for w in s.query("/odom")) > 0


def test_recorder_says_loudly_when_retention_dropped_all_of_the_run(tmp_path, capsys):
    """Messages larger than the budget: each sealed segment is over it and dropped whole.
    The run said "0 kept ... budget met", exit 0; it must say so loudly, exit 3."""
    with open(tmp_path / "big.jsonl", "w") as f:
        for i in range(6):
            f.write(json.dumps({"topic": "/big", "stamp_ns": i * NS, "msg": {"data": os.urandom(30_000).hex()}}) + "\n")
    store = str(tmp_path / "s")
    assert main(["record", str(tmp_path / "big.jsonl"), "--store", store, "--budget", "40KiB",
                 "--codec", "none"]) == 3
    err = capsys.readouterr().err
    assert "met only by DROPPING ALL of this run" in err, err
    assert "retention dropped all 6 messages it stored" in err, err


def test_recorder_ages_in_the_background_within_bounds(tmp_path, capsys):
    jsonl(tmp_path / "run.jsonl", 40_000)  # 2000 s at 20 Hz
    store = str(tmp_path / "s")
    assert main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--budget", "600KiB", "--chunk", "100",
                 "--age-older-than", "600s", "--age-error", "1e-3"]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "windows aged" in err and "budget 600.0 KiB met" in err and "upkeep failed" not in err, err
    with cclogfs.open_store(store, readonly=True) as s:
        windows = list(s.query("/odom"))
        assert [w.seq for w in windows] == list(range(windows[0].seq, windows[0].seq + len(windows)))
        newest_sealed = max(st["end_ns"] for info in s.manifest["segments"] for st in info["streams"].values())
        aged = [w for w in windows if w.aged is not None]
        assert len(aged) > 100
        for w in windows:
            if w.aged is None:
                assert [t for _, t in w.messages()] == [odom(s // (NS // 20)) for s, _ in w.messages()]
            else:
                assert w.end_ns < newest_sealed - 600 * NS  # never younger than the age asked for
                for stamp, text in w.messages():
                    exact = json.loads(odom(stamp // (NS // 20)))
                    for u, v in zip(floats(exact), floats(json.loads(text)), strict=True):
                        assert abs(u - v) <= 1e-3 * (1 + 1e-12)
    assert not check_store(store, deep=True).errors


@pytest.mark.parametrize("budget", [[], ["--budget", "600KiB"]], ids=["aging-never-due", "aging-due"])
def test_recorder_refuses_an_age_error_rule_that_matches_no_field(tmp_path, capsys, budget):
    """`record --age-error 'pose.covarience=0'` was silently ignored (the field rounded by the
    general bound, exit 0) where `compact --error` refuses it. Now aging stops before anything
    ages (with a budget, segments seal and aging is due during the run), the recording goes
    on, and the run ends with the error and exit 1, every message stored exact."""
    jsonl(tmp_path / "run.jsonl", 40_000)  # 2000 s at 20 Hz
    store = str(tmp_path / "s")
    rc = main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--chunk", "100", *budget,
               "--age-older-than", "600s", "--age-error", "1e-3", "--age-error", "pose.covarience=0"])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 1, err
    assert err.strip().endswith(
        "cclog: error: --age-error 'pose.covarience=0' matches no number field of the windows to age (field patterns "
        "start inside msg: 'pose.covariance', not 'msg.pose.covariance'); nothing was aged (no value rounded) and the "
        "recording went on; age the store with `cclog compact --error` and the right field."), err  # fmt: skip
    assert "0 windows aged" in err and "Traceback" not in err
    with cclogfs.open_store(store, readonly=True) as s:
        windows = list(s.query("/odom"))
        assert all(w.aged is None for w in windows)
        texts = [t for w in windows for _, t in w.messages()]
        assert texts[-1] == odom(39_999) and (budget or len(texts) == 40_000)
        if not budget:  # (with one, retention may drop the segment of the run's start record)
            assert [(r.status, r.kept) for r in list_runs(s)] == [("error", 40_000)]


@pytest.mark.parametrize(
    "args, match",
    [(["--age-older-than", "7d"], "give --age-error or --age-max-rate"),
     (["--age-error", "1e-3"], "needs --age-older-than"), (["--budget", "big"], "Size 'big'")],
)  # fmt: skip
def test_recorder_refuses_incomplete_upkeep_flags(tmp_path, capsys, args, match):
    jsonl(tmp_path / "run.jsonl", 10)
    assert main(["record", str(tmp_path / "run.jsonl"), "--store", str(tmp_path / "s"), *args]) == 1
    assert match in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


# -- found in review -------------------------------------------------------------------


def test_aging_with_a_budget_never_drops_the_segment_it_sealed(tmp_path):
    build(tmp_path / "s")  # everything in the active segment
    with cclogfs.open_store(tmp_path / "s") as store:
        report = compact(store, policy=Policy([parse_rule("1e-3")]), older_than_ns=30 * NS, budget=1)
        assert report.over_budget and report.segments_dropped == 0
        assert len(list(store.query("/odom"))) == 12


def test_policies_taking_turns_settle_after_one_pass_each(tmp_path):
    build(tmp_path / "s", windows=2)
    fine, coarse = Policy([parse_rule("1e-3")]), Policy([parse_rule("2.5e-3")])
    with cclogfs.open_store(tmp_path / "s") as store:
        for night in range(6):
            report = compact(store, policy=fine if night % 2 == 0 else coarse)
            assert bool(report.aged) == (night < 2), night
        w = next(iter(store.query("/odom")))
        assert [p["rules"] for p in w.aged] == [[["**", 0.001]], [["**", 0.0025]]]


def test_a_window_aging_leaves_unchanged_gets_no_pass(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", [(1, '{"n": 1, "s": "1.23456"}'), (2, '{"n": 2, "x": [5, -7]}')])
        report = compact(store, policy=Policy([parse_rule("1e-3")]))
        assert report.aged == {}
        assert next(iter(store.query())).aged is None


def test_windows_aged_by_another_writer_are_aged_again_and_their_statement_kept(tmp_path):
    from cclogfs.store import Replacement

    build(tmp_path / "s", windows=2)
    with cclogfs.open_store(tmp_path / "s") as store:
        store.seal()
        store.rewrite(lambda w: Replacement(list(w.messages()), dict(w.meta, aged={"float_abs": 0.01}), flags=1))
        compact(store, policy=Policy([parse_rule("1e-3")]))
        w = next(iter(store.query("/odom")))
        assert w.aged[0] == {"float_abs": 0.01} and w.aged[1]["rules"] == [["**", 0.001]]


def test_cat_says_how_many_printed_windows_were_aged(tmp_path, capsys):
    build(tmp_path / "s", windows=4)
    with cclogfs.open_store(tmp_path / "s") as store:
        compact(store, policy=Policy([parse_rule("1e-3")]), before_ns=10 * NS)
    assert main(["cat", str(tmp_path / "s"), "--topic", "/odom"]) == 0
    captured = capsys.readouterr()
    assert len(captured.out.splitlines()) == 200
    assert "2 of 4 windows were aged" in captured.err


def test_after_a_clock_reset_fresh_windows_are_not_taken_for_old(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        for start in (5000, 5005, 0, 5):  # a simulator restart: its clock starts again at 0
            store.put_window("/odom", [((start + k) * NS, odom(k)) for k in range(5)])
        report = compact(store, policy=Policy([parse_rule("1e-3")]), older_than_ns=30 * NS)
        assert report.aged == {}  # by its largest stamp, the two fresh windows would have aged


def test_budget_counts_the_store_files_not_recovery_side_files(tmp_path):
    build(tmp_path / "s", segment_records=4)
    (tmp_path / "s" / "00000000000000000000.seg.tail-64").write_bytes(b"x" * (1 << 20))
    with cclogfs.open_store(tmp_path / "s") as store:
        report = compact(store, budget=store.data_bytes())
        assert report.segments_dropped == 0 and not report.over_budget


def test_aging_commits_one_segment_at_a_time(tmp_path):
    build(tmp_path / "s", segment_records=4)
    with cclogfs.open_store(tmp_path / "s") as store:
        sizes = []
        real = store.rewrite
        store.rewrite = lambda fn, segments=None: (sizes.append(segments), real(fn, segments=segments))[1]
        compact(store, policy=Policy([parse_rule("1e-3")]))
        assert len(sizes) > 1 and all(len(s) == 1 for s in sizes)


def test_cli_says_to_stop_the_recorder_when_the_store_is_locked(tmp_path, capsys):
    build(tmp_path / "s", windows=2)
    with cclogfs.open_store(tmp_path / "s"):  # a recorder holding the writer lock
        assert main(["compact", str(tmp_path / "s"), "--budget", "1B"]) == 1
    assert "stop the recorder first" in capsys.readouterr().err


# -- found in the review of background aging ------------------------------------------------


def test_overlapping_rewrites_of_one_segment_never_lose_it(tmp_path):
    from cclogfs.store import Replacement

    store = sealed_store(tmp_path / "s", windows=3)

    def slow(w):
        time.sleep(0.05)
        return Replacement(list(w.messages()), dict(w.meta, aged=[{"by": "slow"}]), flags=1)

    def fast(w):
        return Replacement(list(w.messages()), dict(w.meta, aged=[{"by": "fast"}]), flags=1)

    threads = [threading.Thread(target=store.rewrite, args=(fn,), kwargs={"segments": [0]}) for fn in (slow, fast)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    store.close()
    with cclogfs.open_store(tmp_path / "s") as s:  # both ran, one after the other
        assert [w.aged[0]["by"] for w in s.query() if w.seq < 4] in (["fast"] * 4, ["slow"] * 4)
    assert not check_store(str(tmp_path / "s"), deep=True).errors


def test_dry_run_changes_nothing_and_foretells_the_real_run(tmp_path, capsys):
    from cclogfs.upkeep import preview

    build(tmp_path / "s", segment_records=4)
    before = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    policy = Policy([parse_rule("1e-3")])
    with cclogfs.open_store(tmp_path / "s") as writer:  # a recorder holds the lock: still fine
        assert main(["compact", str(tmp_path / "s"), "--older-than", "30s", "--error", "1e-3", "--dry-run"]) == 0
        assert "dry run: nothing changed" in capsys.readouterr().out
        with cclogfs.open_store(tmp_path / "s", readonly=True) as reader:
            aging = preview(reader, policy=policy, older_than_ns=30 * NS)
            dropping = preview(reader, budget=writer.data_bytes() // 2)
    assert {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir() if p.name != "LOCK"} == {
        k: v for k, v in before.items() if k != "LOCK"}
    with cclogfs.open_store(tmp_path / "s") as store:
        done = compact(store, policy=policy, older_than_ns=30 * NS)
    assert {k: v["windows"] for k, v in aging.aged.items()} == {k: v["windows"] for k, v in done.aged.items()}
    build(tmp_path / "t", segment_records=4)
    with cclogfs.open_store(tmp_path / "t") as store:
        real = compact(store, budget=store.data_bytes() // 2)
    assert (dropping.segments_dropped, dropping.dropped) == (real.segments_dropped, real.dropped)


def test_a_rule_is_checked_against_the_fields_of_what_ages(tmp_path, capsys):
    build(tmp_path / "s", windows=3)
    store = str(tmp_path / "s")
    assert main(["compact", store, "--error", "1e-3", "--error", "pose.x=0", "--error", "*.stamp.*=0"]) == 0
    with cclogfs.open_store(store, readonly=True) as s:
        for w in s.query("/odom"):
            assert [json.loads(t)["pose"]["x"] for _, t in w.messages()] == \
                [json.loads(odom(i))["pose"]["x"] for i in range(w.seq // 2 * 50, w.seq // 2 * 50 + 50)]
    policy = Policy([parse_rule("a.b=1"), parse_rule("a.*=1"), parse_rule("c=1"), parse_rule("s=1")])
    assert [r.pattern for r in policy.unmatched(['{"a": {"b": [1.5, 2]}, "s": "1.5"}'])] == ["c", "s"]


def test_retention_keeps_every_run_record_so_a_source_is_still_refused_twice(tmp_path, capsys):
    """Found by attack: `record --budget` dropped the runs' own start and end records (on
    /cclog/runs) with the oldest segments, after which the same file was recorded again (the
    duplicate check reads the runs stream) and `cclog info` listed no run. Retention carries
    the run records of a segment it drops into the active segment (FORMAT.md, "Retention")."""
    jsonl(tmp_path / "run.jsonl", 40_000)
    jsonl(tmp_path / "run2.jsonl", 20_000, hz=40)
    store = str(tmp_path / "s")
    for src in ("run.jsonl", "run2.jsonl"):
        assert main(["record", str(tmp_path / src), "--store", store, "--budget", "256KiB", "--chunk", "100"]) == 0
    capsys.readouterr()
    with cclogfs.open_store(store, readonly=True) as s:
        assert s.dropped()["segments"] >= 3  # the first run's start record was in the first one
        assert "/cclog/runs" not in s.dropped()["streams"]  # carried, not dropped
        runs = list_runs(s)
        assert [(r.number, r.status, r.kept) for r in runs] == [(1, "done", 40_000), (2, "done", 20_000)]
        assert [r.source for r in runs] == [str(tmp_path / "run.jsonl"), str(tmp_path / "run2.jsonl")]
        assert len(list(s.query("/cclog/runs"))) == 4  # each record once
    assert main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--budget", "256KiB"]) == 1
    assert "was recorded into" in capsys.readouterr().err
    assert main(["info", store]) == 0
    out = capsys.readouterr().out
    assert "runs (2, stream /cclog/runs)" in out
    # the table said "40,000 kept"; now what the store holds of each run and what dropped the rest
    assert "40,000 of 40,000; 0 held now (retention dropped 40,000)" in out
    held, dropped = (int(n.replace(",", "")) for n in
                     re.search(r"20,000 of 20,000; ([\d,]+) held now \(retention dropped ([\d,]+)\)", out).groups())  # fmt: skip
    assert held > 0 and dropped > 0 and held + dropped == 20_000
    assert not check_store(store, deep=True).findings


def test_a_small_budget_keeps_the_newest_of_the_run(tmp_path, capsys):
    """Found by attack: under 512 KiB segments stayed 64 KiB, more than a budget of 48 KiB
    holds, so every sealed segment was dropped whole: 0 messages kept, "budget met", exit 0.
    Segments follow the budget down (an eighth of it), so the newest of the run stays."""
    jsonl(tmp_path / "run.jsonl", 8_000)
    store = str(tmp_path / "s")
    assert main(["record", str(tmp_path / "run.jsonl"), "--store", store, "--budget", "48KiB", "--chunk", "100"]) == 0
    err = capsys.readouterr().err
    assert "budget 48.0 KiB met" in err, err
    with cclogfs.open_store(store, readonly=True) as s:
        assert s.data_bytes() <= 48 << 10
        stamps = [t for w in s.query("/odom") for t, _ in w.messages()]
    assert len(stamps) > 1_000 and max(stamps) == 7_999 * NS // 20  # the newest stay


def _damaged_run_record_in_oldest_segment(path, pad: int = 0) -> None:
    """Sealed segments of a run record and a message (of `pad` random hex digits) each; the
    first run record damaged and named in the manifest by `fsck --repair`."""
    from helpers import flip, record_at

    with cclogfs.open_store(path, create=True, segment_records=2) as store:
        for i in range(6):
            rec = {"event": "start", "run": i + 1, "id": str(i), "source": f"in{i}", "options": {}}
            store.put_window("/cclog/runs", [(10**12 + i, json.dumps(rec))], {"kind": "run"})
            store.put_window("/a", [(10**12 + i, json.dumps({"i": i, "pad": os.urandom(pad // 2).hex()}))])
    seg, off, length = record_at(path, 0)
    flip(seg, off + length - 5)
    assert main(["fsck", str(path), "--repair"]) == 4  # damage named, kept


def test_retention_says_the_damage_it_drops(tmp_path, capsys):
    # The damaged run record went with its segment unsaid, and the store was then "clean".
    _damaged_run_record_in_oldest_segment(tmp_path / "s")
    capsys.readouterr()
    assert main(["compact", str(tmp_path / "s"), "--budget", "4KiB", "--json"]) == 0
    out, err = capsys.readouterr()
    (d,) = json.loads(out)["damage_dropped"]
    assert d["segment"] == "00000000000000000000.seg" and d["first_seq"] == 0 and d["end_seq"] == 1
    assert err.count("\n") == 1 and "retention dropped a segment holding damage" in err
    assert "00000000000000000000.seg at offset 32" in err and "/cclog/runs" in err


_COMPACT_KILLED_BEFORE_ITS_DROP = """
import os, signal, sys
from cclogfs.store.fs import FileSystem

def rename(self, src, dst):  # the carried run records synced, the drop not committed
    os.kill(os.getpid(), signal.SIGKILL)

FileSystem.rename = rename
from cclogfs.cli import main
main(["compact", sys.argv[1], "--budget", sys.argv[2]])
"""


def test_a_kill_between_the_carry_and_its_drop_shows_each_run_record_once(tmp_path, capsys):
    # The carried copies sat beside their originals: `cat --topic /cclog/runs` printed the
    # first run's start and end twice (info, by run id, once), until the next drop.
    import subprocess
    import sys

    jsonl(tmp_path / "run.jsonl", 4_000)
    jsonl(tmp_path / "run2.jsonl", 4_000, hz=40)
    store = str(tmp_path / "s")
    for src in ("run.jsonl", "run2.jsonl"):
        assert main(["record", str(tmp_path / src), "--store", store, "--budget", "512KiB", "--chunk", "100"]) == 0
    with cclogfs.open_store(store, readonly=True) as s:
        assert s.sealed_segments()[0].streams["/cclog/runs"]["windows"] == 1  # the first run's start
        budget = f"{s.data_bytes() // 1024 - 1}KiB"  # retention drops the oldest segment, carrying it
    capsys.readouterr()
    assert main(["cat", store, "--topic", "/cclog/runs"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 4
    assert subprocess.run([sys.executable, "-c", _COMPACT_KILLED_BEFORE_ITS_DROP, store, budget]).returncode == -9
    assert main(["cat", store, "--topic", "/cclog/runs"]) == 0
    assert capsys.readouterr().out.splitlines() == lines
    with cclogfs.open_store(store, readonly=True) as s:  # the copy is there, beside its original
        assert len(list(s.query("/cclog/runs", copies=True))) == 5
    assert main(["compact", store, "--budget", budget]) == 0  # the drop done: the copy is the one left
    capsys.readouterr()
    assert main(["cat", store, "--topic", "/cclog/runs"]) == 0
    assert sorted(capsys.readouterr().out.splitlines()) == sorted(lines)
    with cclogfs.open_store(store, readonly=True) as s:
        assert len(list(s.query("/cclog/runs", copies=True))) == 4


def test_a_dry_run_says_the_damage_retention_would_drop(tmp_path, capsys):
    # The real run listed the damage in `damage_dropped` and warned; the dry run said nothing.
    _damaged_run_record_in_oldest_segment(tmp_path / "s")
    capsys.readouterr()
    assert main(["compact", str(tmp_path / "s"), "--budget", "4KiB", "--dry-run", "--json"]) == 0
    (d,) = json.loads(capsys.readouterr().out)["damage_dropped"]
    assert main(["compact", str(tmp_path / "s"), "--budget", "4KiB", "--dry-run"]) == 0
    out, err = capsys.readouterr()
    assert "would drop a segment holding damage (00000000000000000000.seg at offset 32" in out and not err
    assert main(["compact", str(tmp_path / "s"), "--budget", "4KiB", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["damage_dropped"] == [d]  # what the real run then dropped


def test_retention_while_recording_says_the_damage_it_drops(tmp_path, capsys):
    _damaged_run_record_in_oldest_segment(tmp_path / "s", pad=16 << 10)  # 6 x 16 KiB: over 32 KiB
    src = tmp_path / "in.jsonl"
    src.write_text(json.dumps({"topic": "/b", "stamp_ns": 2 * 10**12, "msg": {"x": 1}}) + "\n")
    capsys.readouterr()
    assert main(["record", str(src), "--store", str(tmp_path / "s"), "--append", "--budget", "32KiB"]) == 0
    err = capsys.readouterr().err
    assert "retention dropped a segment holding damage (00000000000000000000.seg at offset 32" in err


@pytest.mark.parametrize("dry", [[], ["--dry-run"]])
def test_the_runs_stream_is_never_aged_and_compact_says_so(tmp_path, capsys, dry):
    # `--stream /cclog/runs` said "nothing to age (no window old enough...)" after sealing
    # the active segment for it, and --dry-run listed the runs as windows it would age.
    src = tmp_path / "in.jsonl"
    src.write_text("".join(json.dumps({"topic": "/b", "stamp_ns": 10**12 + i, "msg": {"x": i / 3}}) + "\n"
                           for i in range(5)))  # fmt: skip
    assert main(["record", str(src), "--store", str(tmp_path / "s")]) == 0
    files = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    for pattern in ("/cclog/runs", "/cclog/*"):
        capsys.readouterr()
        assert main(["compact", str(tmp_path / "s"), "--stream", pattern, "--error", "0.1", *dry]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "/cclog/runs, which is never aged or compacted" in err
    assert {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()} == files
    assert main(["compact", str(tmp_path / "s"), "--stream", "*", "--error", "0.1", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "/b" in out and "/cclog/runs" not in out
