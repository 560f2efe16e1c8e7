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
    assert f"message on {RUNS_STREAM} (at 5)" in capsys.readouterr().err
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [t for w in store.query("/odom") for t, _ in w.messages()] == list(range(5))
        runs = list_runs(store)
        assert [(r.number, r.status) for r in runs] == [(1, "error")]
        assert all(json.loads(text)["event"] in ("start", "end") for w in store.query(RUNS_STREAM)
                   for _, text in w.messages())  # fmt: skip


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
