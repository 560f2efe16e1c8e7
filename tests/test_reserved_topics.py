"""A source message on /cclog/runs (the store's record of its runs) is refused, not stored
into that stream: there `cat` left it out as bookkeeping (exit 0, a topic silently gone)
and `cclog info` read it as a run. Found by attack (/tmp/atk3/runs.jsonl)."""

from __future__ import annotations

import json

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import InvalidInputError
from cclogfs.ingest import SourceMessage, format_line
from cclogfs.pipeline import KeepAll, Logger, record
from cclogfs.runs import RUNS_STREAM, list_runs


def lines(topics):
    return "".join(format_line(t, i, json.dumps({"i": i})) for i, t in enumerate(topics))


def test_record_refuses_a_source_message_on_the_runs_stream(tmp_path, capsys):
    src = tmp_path / "in.jsonl"
    src.write_text(lines(["/odom"] * 5 + [RUNS_STREAM] + ["/odom"] * 5))
    assert main(["record", str(src), "--store", str(tmp_path / "s")]) == 1
    assert (f"cclog: error: {src}, line 6: the message is on {RUNS_STREAM}, the stream this recording writes "
            "itself; leave that topic out with --topic.") in capsys.readouterr().err  # fmt: skip
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [t for w in store.query("/odom") for t, _ in w.messages()] == list(range(5))
        runs = list_runs(store)
        assert [(r.number, r.status) for r in runs] == [(1, "error")]
        assert all(json.loads(text)["event"] in ("start", "end") for w in store.query(RUNS_STREAM)
                   for _, text in w.messages())  # fmt: skip


@pytest.mark.parametrize("layout", ["canonical", "spaced"])
def test_on_error_skip_skips_and_counts_a_line_on_the_runs_stream(tmp_path, capsys, layout):
    """It stopped an --on-error skip run, naming no line (the pipeline's check knew none)."""
    src = tmp_path / "in.jsonl"
    text = lines(["/odom"] * 3 + [RUNS_STREAM] + ["/odom"] * 3)
    src.write_text(text if layout == "canonical" else text.replace('":', '": '))
    assert main(["record", str(src), "--store", str(tmp_path / "s"), "--on-error", "skip"]) == 4
    err = capsys.readouterr().err
    assert f"cclog: skipped: {src}, line 4: the message is on {RUNS_STREAM}" in err
    assert f"{src}: 1 bad lines skipped (--on-error skip)" in err
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [t for w in store.query("/odom") for t, _ in w.messages()] == [0, 1, 2, 4, 5, 6]
        assert [(r.number, r.status, r.kept) for r in list_runs(store)] == [(1, "done", 6)]


def test_a_json_mcap_channel_on_the_runs_stream_is_named_and_skippable(tmp_path, capsys):
    from mcap.writer import Writer

    path = tmp_path / "in.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        odom = w.register_channel("/odom", "json", 0)
        runs = w.register_channel(RUNS_STREAM, "json", 0)
        for t, chan in ((1, odom), (2, runs), (3, odom)):
            w.add_message(chan, log_time=t, data=b'{"x": 1}', publish_time=t)
        w.finish()
    assert main(["record", str(path), "--store", str(tmp_path / "s")]) == 1
    assert (f"cclog: error: {path}, message 2 (logged at 2 ns): the message is on {RUNS_STREAM}, the stream this "
            "recording writes itself") in capsys.readouterr().err  # fmt: skip
    assert main(["record", str(path), "--store", str(tmp_path / "skip"), "--on-error", "skip"]) == 4
    assert f"cclog: skipped: {path}, message 2 (logged at 2 ns)" in capsys.readouterr().err
    with cclogfs.open_store(tmp_path / "skip", readonly=True) as store:
        assert [t for w in store.query("/odom") for t, _ in w.messages()] == [1, 3]


def test_a_ros1_bag_connection_on_the_runs_stream_is_named(tmp_path, capsys):
    from rosbags.rosbag1 import Writer as BagWriter
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    String = ts.types["std_msgs/msg/String"]
    path = tmp_path / "in.bag"
    with BagWriter(path) as bag:
        a = bag.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        b = bag.add_connection(RUNS_STREAM, "std_msgs/msg/String", typestore=ts)
        for t, con in ((1, a), (2, b), (3, a)):
            bag.write(con, t, bytes(ts.serialize_ros1(String(data="hi"), "std_msgs/msg/String")))
    assert main(["record", str(path), "--store", str(tmp_path / "s")]) == 1
    assert (f"cclog: error: {path}, message 2 of the bag (logged at 2 ns): the message is on {RUNS_STREAM}"
            in capsys.readouterr().err)  # fmt: skip
    assert main(["record", str(path), "--store", str(tmp_path / "skip"), "--on-error", "skip"]) == 4
    with cclogfs.open_store(tmp_path / "skip", readonly=True) as store:
        assert [t for w in store.query("/chatter") for t, _ in w.messages()] == [1, 3]


def test_message_by_message_and_logger_refuse_it_too(tmp_path):
    msgs = [SourceMessage("/odom", 1, "{}", ""), SourceMessage(RUNS_STREAM, 2, "{}", "")]
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        with pytest.raises(InvalidInputError, match="writes itself"):
            record(iter(msgs), store, KeepAll())
    with Logger(str(tmp_path / "s2")) as log, pytest.raises(InvalidInputError, match="writes itself"):
        log(RUNS_STREAM, 1, "{}")


def test_keep_all_keeps_a_summary_stream_of_the_source(tmp_path, capsys):
    """An export of a smart store holds /cclog/summary; recording it keeps it as it was."""
    src = tmp_path / "in.jsonl"
    src.write_text(lines(["/odom", "/cclog/summary", "/odom"]))
    assert main(["record", str(src), "--store", str(tmp_path / "s")]) == 0
    assert main(["cat", str(tmp_path / "s")]) == 0
    assert capsys.readouterr().out == src.read_text()
