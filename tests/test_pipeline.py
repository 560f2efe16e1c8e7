"""The pipeline and the record/train/eval commands, on the real TurtleBot bag."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import cclogfs
from cclogfs.classifier.features import parse_odometry
from cclogfs.classifier.testing import inject, odom_texts
from cclogfs.cli import main
from cclogfs.ingest import format_line, open_source
from cclogfs.pipeline import KeepAll, monotonic_runs, parse_span, read_topic, record

ROOT = Path(__file__).resolve().parent.parent


def test_keep_all_chunks_per_topic():
    policy = KeepAll(chunk=3)
    out = []
    for i in range(7):
        out += policy.push("/a" if i % 2 else "/b", i, str(i))
    out += policy.flush()
    assert [(c.topic, [t for t, _ in c.messages]) for c in out] == [
        ("/b", [0, 2, 4]), ("/a", [1, 3, 5]), ("/b", [6])]  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from("abc"), max_size=40), st.integers(1, 5), st.integers(1, 9))
def test_keep_all_push_many_is_push_of_each(topics, chunk, size):
    """The same windows in the same order, and the same open windows left (flush order)."""
    messages = [(t, i, str(i)) for i, t in enumerate(topics)]
    one, many = KeepAll(chunk=chunk), KeepAll(chunk=chunk)
    want = [w for m in messages for w in one.push(*m)]
    got = [w for i in range(0, len(messages), size) for w in many.push_many(messages[i : i + size])]
    assert got == want and list(many.open.items()) == list(one.open.items())
    assert many.flush() == one.flush()


def test_monotonic_runs_keep_every_message_in_order():
    msgs = [(5, "a"), (6, "b"), (3, "c"), (3, "d"), (9, "e"), (1, "f")]
    runs = list(monotonic_runs(msgs))
    assert runs == [[(5, "a"), (6, "b")], [(3, "c"), (3, "d"), (9, "e")], [(1, "f")]]
    assert [m for r in runs for m in r] == msgs


@pytest.mark.parametrize("text, want", [("100", (100, None)), ("4s", (0, 4.0)), ("2.5s", (0, 2.5))])
def test_parse_span(text, want):
    assert parse_span(text) == want


# "nans" and "infs" passed the check and ended `cclog record --before nans` in a ValueError
# (OverflowError for infs) traceback when the window was sized (found by the attack of l-atk8)
@pytest.mark.parametrize("text", ["-1", "x", "4ms", "-2s", "", "nans", "infs", "-infs", "1e400s"])
def test_parse_span_rejects(text):
    with pytest.raises(cclogfs.InvalidInputError, match="message count like 100"):
        parse_span(text)


def test_record_everything_from_a_bag_is_exact(tmp_path, shared_data):
    bag = shared_data("nav2_turtlebot.mcap")
    with open_source(bag) as source:
        want = {}
        for m in source:
            want.setdefault(m.topic, []).append((m.stamp_ns, m.text))
    with cclogfs.open_store(tmp_path / "s", create=True) as store, open_source(bag) as source:
        stats = record(source, store, KeepAll(chunk=150), check_json=False)
        assert stats.messages_in == stats.messages_kept == sum(map(len, want.values()))
        for topic, messages in want.items():
            got = sorted(store.query(topic), key=lambda w: w.seq)
            assert [m for w in got for m in w.messages()] == messages


def smart_fixture(tmp_path, shared_data):
    """A model trained on the first half of /odom, and the second half with injected anomalies."""
    texts = read_topic(str(shared_data("nav2_turtlebot.mcap")), "/odom")
    odom = parse_odometry(t for _, t in texts)
    half = len(odom) // 2
    first, second = odom.take(slice(0, half)), odom.take(slice(half, None))
    t0 = int(second.stamp_ns[0])
    second, e1 = inject(second, "accel", t0 + 10 * 10**9, 1.0)
    second, e2 = inject(second, "spin", t0 + 30 * 10**9, 3.0)
    for name, part in (("train", first), ("test", second)):
        lines = [format_line("/odom", int(s), text) for s, text in zip(part.stamp_ns, odom_texts(part))]
        (tmp_path / f"{name}.jsonl").write_text("".join(lines))
    (tmp_path / "labels.json").write_text(json.dumps({"events": [e1, e2]}))
    return [e1, e2]


def test_train_record_eval_smart_logging(tmp_path, shared_data, capsys):
    events = smart_fixture(tmp_path, shared_data)
    p = lambda name: str(tmp_path / name)  # noqa: E731
    assert main(["train", p("train.jsonl"), "--out", p("model"), "--validate", p("test.jsonl"),
                 "--validate-labels", p("labels.json")]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "trained model" in out and "True Positives" in out
    assert main(["record", p("test.jsonl"), "--store", p("store"), "--model", p("model"),
                 "--before", "2s", "--after", "2s"]) == 0  # fmt: skip
    with cclogfs.open_store(p("store"), readonly=True) as store:
        windows = list(store.query("/odom"))
        assert windows and all("model_id" in w.meta for w in windows)
        for e in events:  # every injected event is inside a stored window
            assert any(w.start_ns <= e["start_ns"] and e["end_ns"] <= w.end_ns for w in windows), e
        kept = sum(w.count for w in windows)
        assert kept < 0.8 * sum(1 for _ in open(p("test.jsonl")))  # smart logging drops most of it
        assert "/cclog/summary" in store.streams()
    assert main(["eval", p("test.jsonl"), "--model", p("model"), "--labels", p("labels.json"),
                 "--before", "2s", "--after", "2s"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "Events recalled" in out and "2 (100.0%)" in out and "Detection delay" in out


def test_model_file_errors(tmp_path, capsys):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "model.json").write_text("{}")
    (tmp_path / "m" / "model.npz").write_bytes(b"")
    (tmp_path / "in.jsonl").write_text(format_line("/odom", 1, "{}") + "\n")
    assert main(["record", str(tmp_path / "in.jsonl"), "--store", str(tmp_path / "s"), "--model",
                 str(tmp_path / "m")]) == 1  # fmt: skip
    assert "model.json is not a" in capsys.readouterr().err


def run_cli(*args, **kw):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "cclogfs", *args], env=env, cwd=ROOT, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)  # fmt: skip


def test_malformed_line_stops_and_keeps_what_came_before(tmp_path):
    lines = [format_line("/odom", i, json.dumps({"i": i})) for i in range(50)]
    lines.insert(30, "{\"topic\": \"/odom\", \"stamp_ns\": 1, \"msg\": {broken\n")
    proc = run_cli("record", "-", "--store", str(tmp_path / "s"))
    out, err = proc.communicate("".join(lines), timeout=60)
    assert proc.returncode == 1 and "line 31" in err
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [t for w in store.query("/odom") for t, _ in w.messages()] == list(range(30))
    proc = run_cli("record", "-", "--store", str(tmp_path / "s2"), "--on-error", "skip")
    out, err = proc.communicate("".join(lines), timeout=60)
    assert proc.returncode == 4 and "skipped" in err and "line 31" in err
    with cclogfs.open_store(tmp_path / "s2", readonly=True) as store:
        assert sum(w.count for w in store.query("/odom")) == 50


def test_sigterm_flushes_and_closes_cleanly(tmp_path):
    proc = run_cli("record", "-", "--store", str(tmp_path / "s"))
    for i in range(20):
        proc.stdin.write(format_line("/odom", i, json.dumps({"i": i})))
    proc.stdin.flush()
    deadline = time.monotonic() + 30
    while not (tmp_path / "s" / "MANIFEST").exists():  # the store is open: the lines are being read
        assert time.monotonic() < deadline
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 143 and "interrupted" in err, err  # 128 + SIGTERM, as shells expect (issue 12)
    with cclogfs.open_store(tmp_path / "s") as store:
        assert store.recovery.clean, err  # closed cleanly, nothing torn
        assert [t for w in store.query("/odom") for t, _ in w.messages()] == list(range(20)), err


def test_logger_embedded_in_a_live_program(tmp_path, shared_data):
    # What examples/ros2_node.py does, with the bag's CDR bytes standing in for rclpy's,
    # fed from two threads like a multi-threaded executor.
    import threading

    from rosbags.highlevel import AnyReader

    from cclogfs.ingest.live import LiveSource
    from cclogfs.pipeline import Logger

    bag = shared_data("nav2_turtlebot.mcap")
    with AnyReader([bag]) as reader:
        raws = [(c.topic, c.msgtype, raw, t) for c, t, raw in reader.messages()]
    with open_source(bag) as source:
        want = sorted((m.topic, m.stamp_ns, m.text) for m in source)
    with Logger(str(tmp_path / "s"), chunk=64) as log:
        live = LiveSource(log)
        by_topic = {}
        for r in raws:
            by_topic.setdefault(r[0], []).append(r)
        # One thread per topic keeps each topic's order, as a ROS executor does per subscription.
        threads = [threading.Thread(target=lambda rs=rs: [live.feed_cdr(t, ty, raw, recv_ns=ns) for t, ty, raw, ns in rs])
                   for rs in by_topic.values()]  # fmt: skip
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        got = sorted((w.name, s, t) for w in store.query() for s, t in w.messages())
    assert got == want


def test_interrupt_while_storing_a_window_loses_nothing(tmp_path):
    # The signal arrives in the middle of put_window: the window taken from the policy
    # is still stored, then the run stops and the rest is flushed.
    from cclogfs.pipeline import interrupt_handler

    class Msg:
        def __init__(self, i):
            self.topic, self.stamp_ns, self.text = "/a", i, str(i)

    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        real_put = store.put_window
        calls = []

        def put(*args, **kw):
            calls.append(1)
            if len(calls) == 2:
                interrupt_handler(2, None)  # as if Ctrl-C arrived now
            return real_put(*args, **kw)

        store.put_window = put
        stats = record((Msg(i) for i in range(10)), store, KeepAll(chunk=3))
        assert stats.interrupted and stats.messages_in == 6
        assert [t for w in sorted(store.query(), key=lambda w: w.seq) for t, _ in w.messages()] == list(range(6))


def test_negative_stamps_round_trip_through_jsonl(tmp_path, capsys):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/a", [(-5, '{"x": 1}'), (3, '{"x": 2}')])
    assert main(["cat", str(tmp_path / "s")]) == 0
    (tmp_path / "out.jsonl").write_text(capsys.readouterr().out)
    with open_source(str(tmp_path / "out.jsonl")) as source:
        assert [(m.stamp_ns, m.text) for m in source] == [(-5, '{"x": 1}'), (3, '{"x": 2}')]
    assert main(["export", str(tmp_path / "s"), "--mcap", str(tmp_path / "o.mcap")]) == 1
    assert "unsigned" in capsys.readouterr().err


def test_parquet_flatten_keeps_colliding_names():
    from cclogfs.export.parquet import flatten

    assert flatten({"a.b": 1, "a": {"b": 2}}) == {"a.b": 1, "a.b~": 2}


def test_collect_mode_writes_a_labelled_dataset_that_train_learns_from(tmp_path, shared_data, capsys):
    events = smart_fixture(tmp_path, shared_data)
    p = lambda name: str(tmp_path / name)  # noqa: E731
    assert main(["record", p("test.jsonl"), "--store", p("all"), "--features-out", p("vectors"),
                 "--labels", p("labels.json")]) == 0  # fmt: skip
    meta = json.loads((tmp_path / "vectors" / "dataset.json").read_text())
    assert meta["nominal"] > 100 and meta["anomalous"] > 0
    assert len(list((tmp_path / "vectors" / "anomalous").glob("*.npy"))) == meta["anomalous"]
    assert main(["train", p("vectors"), "--out", p("model")]) == 0
    assert "trained model" in capsys.readouterr().out
    assert events


def test_a_bad_message_is_refused_at_the_door_and_takes_no_window_with_it(tmp_path):
    from cclogfs.pipeline import Logger

    with Logger(str(tmp_path / "s"), chunk=3) as log:
        log("/a", 1, '{"v":1}')
        log("/a", 2, '{"v":2}')
        with pytest.raises(cclogfs.InvalidInputError, match="'/a' at 3 is not well-formed JSON"):
            log("/a", 3, '{"v":3')
        log("/a", 4, '{"v":4}')
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [t for w in store.query() for t, _ in w.messages()] == [1, 2, 4]
    with pytest.raises(cclogfs.StoreError, match="closed"):
        log("/a", 5, "{}")


def test_unchecked_json_still_gets_the_stores_other_checks_at_the_door(tmp_path):
    """check_json=False skips only the parse: a text the store would refuse (a lone
    surrogate) stops the run at that message, and the window it would have joined is kept."""
    from types import SimpleNamespace as M

    messages = [M(topic="/a", stamp_ns=1, text='{"v":1}'), M(topic="/a", stamp_ns=2, text='"\ud800"')]
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        with pytest.raises(cclogfs.InvalidInputError, match="'/a' at 2 is not valid UTF-8"):
            record(messages, store, KeepAll(chunk=3), check_json=False)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [t for w in store.query() for t, _ in w.messages()] == [1]


def test_smart_logging_without_the_models_odometry_says_so(tmp_path, shared_data, capsys):
    # A smart recording of topics without the model's /odom scored nothing and kept
    # nothing, and said only "0 kept", as if nothing anomalous had happened.
    smart_fixture(tmp_path, shared_data)
    p = lambda name: str(tmp_path / name)  # noqa: E731
    assert main(["train", p("train.jsonl"), "--out", p("model")]) == 0
    capsys.readouterr()
    assert main(["record", str(shared_data("tf_example.bag")), "--store", p("store"), "--model", p("model")]) == 1
    err = capsys.readouterr().err
    assert "/odom" in err and "--odom-topic" in err, err  # refused before anything is stored (issue 12)


class _Lists:
    """A source that also hands over its messages a list at a time, as JsonlSource does."""

    def __init__(self, messages, size):
        self.messages, self.size = messages, size

    def batches(self):
        for i in range(0, len(self.messages), self.size):
            yield self.messages[i : i + self.size]


def _record_both(tmp_path, messages, size, check_json, **keep):
    """What `record` stores and counts, and the error it stops with, from a message
    at a time (a plain list) and from lists (`batches`)."""
    out = []
    for name, source in (("each", list(messages)), ("lists", _Lists(list(messages), size))):
        with cclogfs.open_store(tmp_path / name, create=True) as store:
            try:
                stats, error = record(source, store, KeepAll(**keep), check_json=check_json), None
            except cclogfs.InvalidInputError as err:
                stats, error = None, str(err)
            windows = [(w.name, w.meta, list(w.messages())) for w in sorted(store.query(), key=lambda w: w.seq)]
        out.append((windows, stats and {**vars(stats), "seconds": 0}, error))
    return out


@pytest.mark.parametrize("size", [1, 7, 64, 1000])
@pytest.mark.parametrize("keep", [{"chunk": 5}, {"chunk": 200, "chunk_s": 0.000_000_02}])
def test_a_list_at_a_time_stores_and_counts_the_same(tmp_path, size, keep):
    from cclogfs.ingest.base import SourceMessage as M

    topics = ["/a", "/b", "/a", "/c", "/a"]
    messages = [M(topics[i % 5], i * 7 - (i % 11 == 3) * 20, json.dumps({"i": i, "s": "é" * (i % 3)}), "")
                for i in range(300)]  # fmt: skip
    each, lists = _record_both(tmp_path, messages, size, False, **keep)
    assert each == lists and each[1]["messages_kept"] == 300 and len(each[0]) > 60


@pytest.mark.parametrize("check_json, bad", [(False, '"\ud800"'), (True, '{"v": 1'), (False, b"{}")])
def test_a_list_at_a_time_stops_at_the_same_message(tmp_path, check_json, bad):
    """The bad message's error, after the messages before it in its list were stored."""
    from cclogfs.ingest.base import SourceMessage as M

    messages = [M("/a", i, bad if i == 23 else f'{{"v": {i}}}', "") for i in range(40)]
    each, lists = _record_both(tmp_path, messages, 10, check_json, chunk=4)
    assert each == lists and "at 23" in each[2]
    assert [t for _, _, ms in each[0] for t, _ in ms] == list(range(23))
