"""Issue 12: each `cclog record` is an identified run in the store (/cclog/runs: source,
its fingerprint, start, end, options); recording the same source again is refused unless
--append; `info` lists the runs; readers leave the runs' records out unless named."""

import json
import shutil
import signal
import subprocess
import sys
import time

import pytest
from mcap.reader import make_reader

import cclogfs
from cclogfs.cli import main
from cclogfs.runs import RUNS_STREAM, begin_run, list_runs, source_fingerprint
from helpers import flip, record_at

CCLOG = [sys.executable, "-m", "cclogfs"]


def messages(store_path) -> int:
    with cclogfs.open_store(store_path, readonly=True) as store:
        return sum(st["messages"] for name, st in store.streams().items() if name != RUNS_STREAM)


def info_json(store_path, capsys) -> dict:
    capsys.readouterr()
    assert main(["info", str(store_path), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_recording_the_same_bag_again_is_refused(shared_data, tmp_path, capsys):
    bag, store = str(shared_data("tf_example.bag")), tmp_path / "s"
    assert main(["record", bag, "--store", str(store)]) == 0
    assert messages(store) == 518
    capsys.readouterr()
    # Before runs, this stored the bag a second time: 1,036 messages, every one twice.
    assert main(["record", bag, "--store", str(store)]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1, err
    assert "recorded into" in err and "as run 1" in err and "518 messages kept" in err and "--append" in err
    assert messages(store) == 518
    # A copy under another name is the same source (its content), so refused too.
    copy = tmp_path / "copy.bag"
    shutil.copyfile(bag, copy)
    assert main(["record", str(copy), "--store", str(store), "--topic", "/tf"]) == 1
    assert "as run 1" in capsys.readouterr().err
    assert len(info_json(store, capsys)["runs"]) == 1  # refused runs leave no trace


def test_append_records_again_and_info_lists_both_runs(shared_data, tmp_path, capsys):
    bag, store = str(shared_data("tf_example.bag")), tmp_path / "s"
    assert main(["record", bag, "--store", str(store)]) == 0
    assert main(["record", bag, "--store", str(store), "--append", "--topic", "/tf"]) == 0
    assert messages(store) == 518 + 517
    runs = info_json(store, capsys)["runs"]
    assert [r["run"] for r in runs] == [1, 2] and {r["status"] for r in runs} == {"done"}
    assert runs[0]["source"] == runs[1]["source"] == bag
    assert runs[0]["fingerprint"] == runs[1]["fingerprint"] == source_fingerprint(bag)
    assert runs[0]["options"] == {} and runs[1]["options"] == {"append": True, "topic": ["/tf"]}
    assert runs[1]["topics_kept"] == {"/tf": 517} and runs[0]["messages_kept"] == 518
    assert runs[0]["start_ns"] < runs[0]["end_ns"] <= runs[1]["start_ns"] < runs[1]["end_ns"]
    assert runs[0]["cclog"] == cclogfs.__version__
    assert main(["info", str(store)]) == 0
    out = capsys.readouterr().out
    assert "runs (2, stream /cclog/runs)" in out and "--append --topic /tf" in out
    assert RUNS_STREAM not in out.split("runs (")[0]  # not in the streams table and its totals


def test_another_source_needs_no_append(shared_data, tmp_path, capsys):
    store = tmp_path / "s"
    assert main(["record", str(shared_data("tf_example.bag")), "--store", str(store)]) == 0
    # The ROS 2 bag directory of the same robot: other bytes, another source.
    assert main(["record", str(shared_data("tf_example")), "--store", str(store)]) == 0
    runs = info_json(store, capsys)["runs"]
    assert runs[1]["fingerprint"]["files"] == 2 and runs[0]["fingerprint"] != runs[1]["fingerprint"]


def test_cat_and_export_leave_the_runs_out_unless_named(shared_data, tmp_path, capsys):
    bag, store = str(shared_data("tf_example.bag")), tmp_path / "s"
    assert main(["convert", bag, "-o", str(tmp_path / "a.jsonl")]) == 0
    assert main(["record", str(tmp_path / "a.jsonl"), "--store", str(store)]) == 0
    capsys.readouterr()
    assert main(["cat", str(store)]) == 0
    assert capsys.readouterr().out == (tmp_path / "a.jsonl").read_text()  # byte for byte, as before runs
    assert main(["cat", str(store), "--topic", RUNS_STREAM]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [(x["topic"], x["msg"]["event"], x["msg"]["run"]) for x in lines] == [
        (RUNS_STREAM, "start", 1), (RUNS_STREAM, "end", 1)]  # fmt: skip
    assert lines[0]["msg"]["source"] == str(tmp_path / "a.jsonl") and lines[1]["msg"]["messages_kept"] == 518
    assert main(["export", str(store), "--mcap", str(tmp_path / "o.mcap")]) == 0
    with open(tmp_path / "o.mcap", "rb") as f:
        topics = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert topics == {"/tf", "/tf_static"}


def _feed(proc, n: int) -> None:
    for i in range(n):
        proc.stdin.write(json.dumps({"topic": "/a", "stamp_ns": 10**18 + i, "msg": {"i": i}}) + "\n")
    proc.stdin.flush()


def _wait_started(store_path, runs: int, timeout: float = 60) -> None:
    """Until a reader sees `runs` runs: the start record is synced before the first message
    is read (a fixed sleep was not enough on a loaded machine)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with cclogfs.open_store(store_path, readonly=True) as store:
                if len(list_runs(store)) == runs:
                    return
        except cclogfs.CclogError:
            pass  # not created yet
        time.sleep(0.1)
    raise TimeoutError(f"{store_path}: not {runs} runs after {timeout} s")


def test_an_interrupted_and_a_killed_run_are_told_apart(tmp_path, capsys):
    store = tmp_path / "s"
    stored = []
    for n, sig in enumerate((signal.SIGINT, signal.SIGKILL), start=1):
        proc = subprocess.Popen([*CCLOG, "record", "-", "--store", str(store), "--sync-ms", "50"],
                                stdin=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)  # fmt: skip
        try:
            _feed(proc, 100)  # the pipe stays open: the run waits for more
            _wait_started(store, runs=n)
            time.sleep(0.5)
            proc.send_signal(sig)
        finally:
            proc.wait(timeout=60)
        assert proc.returncode == (130 if sig == signal.SIGINT else -9)
        stored.append(messages(store))
    runs = info_json(store, capsys)["runs"]
    assert [(r["run"], r["source"], r["status"]) for r in runs] == [(1, "-", "interrupted"), (2, "-", "unfinished")]
    assert runs[0]["signal"] == "SIGINT" and runs[0]["messages_kept"] == stored[0] > 0  # what it stored
    assert runs[1]["end_ns"] is None and "messages_kept" not in runs[1]
    assert main(["info", str(store)]) == 0
    out = capsys.readouterr().out
    assert "interrupted (SIGINT)" in out and "interrupted: no end record (killed" in out


def test_stdin_is_never_refused(tmp_path):
    line = json.dumps({"topic": "/a", "stamp_ns": 5, "msg": {}}) + "\n"
    for _ in range(2):  # what comes on a pipe has no identity to compare
        done = subprocess.run([*CCLOG, "record", "-", "--store", str(tmp_path / "s")], input=line, text=True,
                              capture_output=True, timeout=60)  # fmt: skip
        assert done.returncode == 0, done.stderr
    assert messages(tmp_path / "s") == 2


def test_library_runs_start_before_and_end_after(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        run = begin_run(store, "robot-1 live", options={"model": "m"}, master="http://robot:11311")
        assert [(r.number, r.status, r.end) for r in list_runs(store)] == [(1, "unfinished", None)]
        store.put_window("/odom", [(1, "{}")])
        run.end("done", messages_in=1, messages_kept=1)
        run.end("error")  # once only
        second = begin_run(store, "robot-1 live")
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        runs = list_runs(store)
    assert [(r.number, r.status, r.kept) for r in runs] == [(1, "done", 1), (2, "unfinished", None)]
    assert runs[0].options == {"model": "m"} and runs[0].start["master"] == "http://robot:11311"
    assert runs[1].id == second.id != runs[0].id


def stream_messages(store_path, names=None) -> int:
    with cclogfs.open_store(store_path, readonly=True) as store:
        return sum(st["messages"] for name, st in store.streams().items()
                   if name != RUNS_STREAM and (names is None or name in names))  # fmt: skip


def test_info_says_what_compaction_dropped_of_a_run(shared_data, tmp_path, capsys):
    """l-atk6: after `compact --max-rate` the runs table still said "8,197 of 8,197 kept"
    while the store held a few hundred of them."""
    store = tmp_path / "s"
    assert main(["record", str(shared_data("nav2_turtlebot.mcap")), "--store", str(store)]) == 0
    run = info_json(store, capsys)["runs"][0]
    assert run["messages_held"] == run["messages_kept"] == 8197 and "dropped_since" not in run
    assert main(["compact", str(store), "--max-rate", "2"]) == 0
    held = stream_messages(store)
    assert held < 1000  # ~2 msg/s of each stream over ~97 s
    run = info_json(store, capsys)["runs"][0]
    assert run["messages_kept"] == 8197 and run["messages_held"] == held
    assert run["dropped_since"] == 8197 - held and run["dropped_by"] == "compaction"
    assert main(["info", str(store)]) == 0
    assert f"8,197 of 8,197; {held:,} held now (compaction dropped {8197 - held:,})" in capsys.readouterr().out


def test_messages_held_counts_each_run_apart(shared_data, tmp_path, capsys):
    bag, store = str(shared_data("tf_example.bag")), tmp_path / "s"
    assert main(["record", bag, "--store", str(store)]) == 0
    assert main(["record", bag, "--store", str(store), "--append", "--topic", "/tf"]) == 0
    runs = info_json(store, capsys)["runs"]
    assert [r["messages_held"] for r in runs] == [518, 517] and not any("dropped_since" in r for r in runs)


def test_messages_held_leaves_the_recorders_summaries_out(recorded_smart, capsys):
    run = info_json(recorded_smart / "s", capsys)["runs"][0]
    assert run["summaries"] > 0 and run["messages_kept"] > 0
    assert run["messages_held"] == run["messages_kept"] == stream_messages(recorded_smart / "s", {"/odom", "/tf"})
    assert "dropped_since" not in run


@pytest.fixture
def recorded_smart(shared_data, tmp_path):
    from cclogfs.jsontext.lines import format_line
    from cclogfs.pipeline import read_topic

    bag = str(shared_data("nav2_turtlebot.mcap"))
    train = tmp_path / "train.jsonl"
    train.write_text("".join(format_line("/odom", s, t) for s, t in read_topic(bag, "/odom")[:400]))
    assert main(["train", str(train), "--out", str(tmp_path / "m")]) == 0
    assert main(["record", bag, "--store", str(tmp_path / "s"), "--model", str(tmp_path / "m"), "--force-model",
                 "--topic", "/tf"]) == 0  # fmt: skip
    return tmp_path


def test_info_walks_the_store_once(shared_data, tmp_path, capsys, monkeypatch):
    """l-left8: info walked every window twice (the window count, reading each record's
    meta, then each run's messages held). One walk, the same answer: each run's held
    messages are its windows' counts, retention having dropped part of the first run."""
    from cclogfs.store import Store

    store = tmp_path / "s"
    assert main(["record", str(shared_data("nav2_turtlebot.mcap")), "--store", str(store), "--budget", "512KiB"]) == 0
    assert main(["record", str(shared_data("tf_example.bag")), "--store", str(store), "--append"]) == 0
    capsys.readouterr()
    assert main(["compact", str(store), "--budget", "200KiB"]) == 0
    whole = []
    query = Store.query

    def counted(self, name=None, *args, **kw):
        if name is None:
            whole.append(name)
        return query(self, name, *args, **kw)

    monkeypatch.setattr(Store, "query", counted)
    runs = info_json(store, capsys)["runs"]
    assert len(whole) == 1  # was 2
    monkeypatch.undo()
    with cclogfs.open_store(store, readonly=True) as s:
        windows = [(w.seq, w.count) for w in s.query() if w.name != RUNS_STREAM]
        spans = [(r.start_seq, r.end_seq) for r in list_runs(s)]
    for r, (start, end) in zip(runs, spans, strict=True):
        assert r["messages_held"] == sum(n for seq, n in windows if start < seq < end)
    assert runs[0]["messages_held"] < 8197 == runs[0]["messages_kept"] and runs[0]["dropped_by"] == "retention"
    assert runs[1]["messages_held"] == runs[1]["messages_kept"] == 518


def _record_then_damage_first_start(tmp_path, capsys):
    """A JSON-lines source recorded once, then the run's start record flipped and named by fsck."""
    src, store = tmp_path / "in.jsonl", tmp_path / "s"
    src.write_text("".join(json.dumps({"topic": "/b", "stamp_ns": 10**12 + i, "msg": {"x": i}}) + "\n" for i in range(3)))
    assert main(["record", str(src), "--store", str(store)]) == 0
    with cclogfs.open_store(store, readonly=True) as st:
        (start,) = [w.seq for w in st.query(RUNS_STREAM)][:1]
    seg, off, length = record_at(store, start)
    flip(seg, off + length - 5)
    assert main(["fsck", str(store)]) == 1
    capsys.readouterr()
    return src, store, seg.name, off


def test_a_damaged_run_record_refuses_recording_without_append(tmp_path, capsys):
    # It was recorded again with only a damage warning, its messages then stored twice.
    src, store, seg, off = _record_then_damage_first_start(tmp_path, capsys)
    assert main(["record", str(src), "--store", str(store)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{seg} at offset {off}" in err
    assert "cclog fsck --repair" in err and "--append" in err
    assert messages(store) == 3
    assert main(["record", str(src), "--store", str(store), "--append"]) == 0
    assert messages(store) == 6


def test_damage_on_a_message_stream_does_not_refuse_recording(tmp_path, capsys):
    src, store = tmp_path / "in.jsonl", tmp_path / "s"
    src.write_text(json.dumps({"topic": "/b", "stamp_ns": 10**12, "msg": {"x": 1}}) + "\n")
    assert main(["record", str(src), "--store", str(store)]) == 0
    with cclogfs.open_store(store, readonly=True) as st:
        (seq,) = [w.seq for w in st.query("/b")]
    seg, off, length = record_at(store, seq)
    flip(seg, off + length - 5)
    src.write_text(json.dumps({"topic": "/b", "stamp_ns": 10**12 + 1, "msg": {"x": 2}}) + "\n")
    assert main(["record", str(src), "--store", str(store)]) == 0
    assert "damage below the synced point" in capsys.readouterr().err


@pytest.mark.parametrize("start", [{}, {"options": ["--topic", "/a"], "source": 7}])
def test_info_lists_a_start_record_another_tool_wrote_without_our_fields(tmp_path, capsys, start):
    # A /cclog/runs start record without "options" (written by another tool through the
    # library) ended `cclog info` in KeyError: 'options' (found by l-left9)
    store_path = tmp_path / "s"
    with cclogfs.open_store(store_path, create=True) as store:
        rec = {"event": "start", "run": 1, "id": "abc", **start}
        store.put_window(RUNS_STREAM, [(1, json.dumps(rec))], {"kind": "run"})
        store.put_window("/a", [(2, '{"x": 1}')])
    capsys.readouterr()
    assert main(["info", str(store_path)]) == 0
    out = capsys.readouterr().out
    assert "no end record" in out
    (run,) = info_json(store_path, capsys)["runs"]
    assert run["options"] == {} and isinstance(run["source"], str)
