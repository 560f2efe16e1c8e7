"""Smart logging keeps the odometry its model cannot score (NaN or infinite values), every
message, and the end summary says how many and the first. Before, a real run whose odometry
went to inf after 4,000 messages (past the 3,000 `record` checks before it starts) kept
none of the 5,360 and exited 0 with a numpy RuntimeWarning; all-NaN odometry on stdin kept
nothing, exit 0, not a word."""

import json

import pytest

import cclogfs

from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line
from cclogfs.pipeline import Logger, read_topic
from conftest import shared_data_file


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    d = tmp_path_factory.mktemp("m")
    assert main(["train", str(shared_data_file("long/slamfail_hospital.mcap")), "--out", str(d / "model")]) == 0
    return str(d / "model")


@pytest.fixture(scope="module")
def passage():
    return read_topic(str(shared_data_file("long/slamfail_long_passage.mcap")), "/odom")


def broken(pairs, first, value):
    """The JSONL of `pairs` with pose.position.x `value` from message `first` (0-based) on."""
    out = []
    for i, (stamp, text) in enumerate(pairs):
        if i >= first:
            m = json.loads(text)
            m["pose"]["pose"]["position"]["x"] = value
            text = json.dumps(m)
        out.append(format_line("/odom", stamp, text))
    return "".join(out)


def stored_odometry(store, capsys):
    assert main(["cat", store, "--topic", "/odom"]) == 0
    return [json.loads(line) for line in capsys.readouterr().out.splitlines()]


def test_odometry_gone_to_inf_is_kept_every_message(tmp_path, capsys, model, passage):
    src = tmp_path / "inf.jsonl"
    src.write_text(broken(passage, 4000, float("inf")))
    store = str(tmp_path / "s")
    assert main(["record", str(src), "--store", store, "--model", model]) == 0
    err = capsys.readouterr().err
    assert f"{src}: 5,360 /odom messages had NaN or infinite values (the first at " in err, err
    assert "in pose.position.x): the model cannot score them, so every one was kept" in err, err
    assert "RuntimeWarning" not in err
    kept = {m["stamp_ns"] for m in stored_odometry(store, capsys)}
    assert {s for s, _ in passage[4000:]} <= kept


def test_all_nan_odometry_on_stdin_is_kept_not_refused(tmp_path, capsys, monkeypatch, model, passage):
    import io

    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BytesIO(broken(passage[:500], 0, float("nan")).encode())))
    store = str(tmp_path / "s")
    assert main(["record", "-", "--store", store, "--model", model]) == 0
    assert "-: 500 /odom messages had NaN or infinite values" in capsys.readouterr().err
    assert len(stored_odometry(store, capsys)) == 500


def test_the_logger_keeps_them_message_by_message(tmp_path, capsys, model, passage):
    """The Python API hands messages one at a time (`push`, not `push_many`)."""
    lines = broken(passage[:300], 100, float("nan")).splitlines()
    with Logger(str(tmp_path / "s"), model=model) as log:
        for line in lines:
            m = json.loads(line)
            log("/odom", m["stamp_ns"], json.dumps(m["msg"]))
    assert log.policy.unscored == 200 and log.policy.first == (passage[100][0], "pose.position.x")
    kept = {m["stamp_ns"] for m in stored_odometry(str(tmp_path / "s"), capsys)}
    assert {s for s, _ in passage[100:300]} <= kept


def test_budget_on_a_new_store_names_no_earlier_runs(tmp_path, capsys, model, passage):
    """Found by attack: with --model and --budget, retention dropping this run's own
    /cclog/summary records was told as "retention also dropped 1 messages of earlier runs"
    on a store this run had made: the summaries were counted as dropped messages, but not as
    this run's (the end summary counts them apart)."""
    src = tmp_path / "nan.jsonl"
    src.write_text(broken(passage, 500, float("nan")))
    store = str(tmp_path / "s")
    assert main(["record", str(src), "--store", store, "--model", model, "--budget", "48KiB"]) in (0, 3)
    err = capsys.readouterr().err
    assert "then retention DROPPED the oldest" in err, err
    with cclogfs.open_store(store, readonly=True) as s:
        assert s.dropped()["streams"]["/cclog/summary"]["messages"] >= 1  # the case: its own summaries went
    assert "of earlier runs" not in err, err
