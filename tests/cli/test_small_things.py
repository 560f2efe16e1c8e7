"""Issue 12 item 9: --version, errors in the CLI's words, the summary stream not counted as
messages kept, stream types in `info`."""


import json

import pytest

import cclogfs
from cclogfs.cli import main


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out == f"cclog {cclogfs.__version__}\n"


def test_errors_name_the_cli_not_the_python_api(tmp_path, capsys):
    assert main(["cat", str(tmp_path / "nothing")]) == 1
    err = capsys.readouterr().err
    assert "create=True" not in err and "cclog record" in err
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/a", [(1, "{}")])
        assert main(["record", "-", "--store", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert "readonly=True" not in err and "locked" in err


def test_messages_kept_does_not_count_the_summary_stream(shared_data, tmp_path, capsys):
    from cclogfs.jsontext.lines import format_line
    from cclogfs.pipeline import read_topic

    odom = read_topic(str(shared_data("nav2_turtlebot.mcap")), "/odom")
    (tmp_path / "t.jsonl").write_text("".join(format_line("/odom", s, t) for s, t in odom[:400]))
    assert main(["train", str(tmp_path / "t.jsonl"), "--out", str(tmp_path / "m")]) == 0
    (tmp_path / "all.jsonl").write_text("".join(format_line("/odom", s, t) for s, t in odom))
    capsys.readouterr()
    assert main(["record", str(tmp_path / "all.jsonl"), "--store", str(tmp_path / "s"), "--model",
                 str(tmp_path / "m"), "--force-model"]) == 0  # fmt: skip
    line = capsys.readouterr().err
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        streams = store.streams()
    assert streams["/cclog/summary"]["messages"] > 0
    assert f"{len(odom):,} messages in, {streams['/odom']['messages']:,} kept" in line
    # nor the summary's records as windows of what was kept ("0 kept ... in 8 windows" when
    # the 8 were summaries, found by attack)
    odom_windows, summaries = streams["/odom"]["windows"], streams["/cclog/summary"]["windows"]
    assert f" in {odom_windows:,} windows (and {summaries:,} summaries on /cclog/summary)" in line, line
    # `info` (table and --json) agrees with the end summary: the run's windows count was
    # the summaries' too (found by the attack of l-atk5)
    assert main(["info", str(tmp_path / "s"), "--json"]) == 0
    run = __import__("json").loads(capsys.readouterr().out)["runs"][0]
    assert (run["windows"], run["summaries"]) == (odom_windows, summaries), run
    assert main(["info", str(tmp_path / "s")]) == 0
    assert f" {odom_windows:,} (+{summaries:,} summaries) " in capsys.readouterr().out


def test_info_shows_stream_types(shared_data, tmp_path, capsys):
    assert main(["record", str(shared_data("tf_example.bag")), "--store", str(tmp_path / "s")]) == 0
    capsys.readouterr()
    assert main(["info", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "tf2_msgs/msg/TFMessage" in out and " type" in out


def test_cat_prints_a_utf8_topic_as_it_came_in(tmp_path, capsys):
    """l-left8: cat printed "/cámara" as "/c\\u00e1mara" (the msg beside it raw UTF-8)."""
    import json

    lines = ['{"topic": "/cámara", "stamp_ns": 1, "msg": {"a": "ñ"}}\n',
             '{"topic": "/línea\\u2028sep", "stamp_ns": 2, "msg": {}}\n']  # fmt: skip
    (tmp_path / "in.jsonl").write_text("".join(lines), encoding="utf-8")
    assert main(["record", str(tmp_path / "in.jsonl"), "--store", str(tmp_path / "s")]) == 0
    capsys.readouterr()
    assert main(["cat", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert out.splitlines(keepends=True) == lines  # each line one line, as valid JSON
    assert [json.loads(line)["topic"] for line in out.splitlines()] == ["/cámara", "/línea\u2028sep"]


def test_fsck_help_does_not_say_it_changes_nothing_when_it_repairs(capsys):
    # its description said "Changes nothing." above its own --repair (found by the attack of l-atk8)
    with pytest.raises(SystemExit):
        main(["fsck", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "Changes nothing." not in out and "Changes nothing, unless --repair is given." in out


def test_cat_takes_negative_times_as_stored_stamps_can_be(tmp_path, capsys):
    # `cat --start -1` was refused ("not understood") although such stamps are stored and shown.
    src = tmp_path / "neg.jsonl"
    src.write_text("".join(json.dumps({"topic": "/n", "stamp_ns": t, "msg": {"t": t}}) + "\n"
                           for t in (-3_000_000_000, -500_000_000, 5)))  # fmt: skip
    assert main(["record", str(src), "--store", str(tmp_path / "s")]) == 0
    capsys.readouterr()
    assert main(["cat", str(tmp_path / "s"), "--start", "-1"]) == 0
    assert [json.loads(line)["stamp_ns"] for line in capsys.readouterr().out.splitlines()] == [-500_000_000, 5]
    assert main(["cat", str(tmp_path / "s"), "--end=-1000000000ns"]) == 0
    assert [json.loads(line)["stamp_ns"] for line in capsys.readouterr().out.splitlines()] == [-3_000_000_000]
