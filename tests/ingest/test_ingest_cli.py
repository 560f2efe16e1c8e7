"""`cclog convert`: sources to JSONL that reads back to the same texts."""

from __future__ import annotations

import io
import sys

import pytest

from cclogfs.cli import build_parser, main
from cclogfs.ingest import JsonlSource, format_line, open_source


@pytest.mark.parametrize("name", ["nav2_turtlebot.mcap", "tf_example.bag", "tf_example"])
def test_convert_then_read_back(shared_data, tmp_path, name):
    src = shared_data(name)
    out = tmp_path / "out.jsonl"
    assert main(["convert", str(src), "-o", str(out)]) == 0
    with open_source(src) as s:
        expect = [(m.topic, m.stamp_ns, m.text) for m in s]
    with JsonlSource(out) as j:
        assert [(m.topic, m.stamp_ns, m.text) for m in j] == expect
    # JSONL in, JSONL out: the same bytes.
    again = tmp_path / "again.jsonl"
    assert main(["convert", str(out), "-o", str(again)]) == 0
    assert again.read_bytes() == out.read_bytes()


def test_convert_topic_selection(shared_data, tmp_path):
    out = tmp_path / "odom.jsonl"
    src = shared_data("nav2_turtlebot.mcap")
    assert main(["convert", str(src), "-o", str(out), "--topic", "/odom", "--topic", "/amcl_pose"]) == 0
    topics = {m.topic for m in JsonlSource(out)}
    assert topics == {"/odom", "/amcl_pose"}
    assert sum(1 for _ in JsonlSource(out)) == 2639 + 135


def test_convert_bad_lines(tmp_path, capsys, monkeypatch):
    good = format_line("/a", 1, '{"x": 1}')
    bad = tmp_path / "bad.jsonl"
    bad.write_text(good + "{not json\n" + good)
    out = tmp_path / "out.jsonl"
    assert main(["convert", str(bad), "-o", str(out)]) == 1
    assert "bad.jsonl, line 2: invalid JSON" in capsys.readouterr().err
    assert main(["convert", str(bad), "-o", str(out), "--on-error", "skip"]) == 4  # lines left out: exit 4
    assert "skipped: " in capsys.readouterr().err and out.read_text() == good * 2
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(good.encode())))
    assert main(["convert", "-", "-o", "-"]) == 0
    assert capsys.readouterr().out == good


def test_convert_unknown_file(tmp_path, capsys):
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    assert main(["convert", str(tmp_path / "x.csv"), "-o", str(tmp_path / "o.jsonl")]) == 1
    assert "x.csv is of an unknown file type" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["convert", "cat", "export"])
def test_help_has_examples(command, capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args([command, "--help"])
    text = capsys.readouterr().out
    assert "examples:" in text and f"cclog {command} " in text


def test_jsonl_file_whose_first_line_is_cut_is_read_as_jsonl(tmp_path, capsys):
    # A log cut at its start (rotated, `tail -c`) begins mid-line: it was "of an unknown
    # file type" even with --on-error skip, naming no line (found by the attack of l-atk8)
    good = '{"topic": "/a", "stamp_ns": 1, "msg": {"x": 1}}\n'
    src = tmp_path / "cut.jsonl"
    src.write_text('2.5}}}\n' + good)
    assert main(["convert", str(src), "-o", "-"]) == 1
    assert "cut.jsonl, line 1: invalid JSON" in capsys.readouterr().err
    assert main(["convert", str(src), "-o", "-", "--on-error", "skip"]) == 4  # a line left out: exit 4
    assert capsys.readouterr().out == good
