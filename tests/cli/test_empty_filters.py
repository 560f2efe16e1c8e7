"""Issue 12 item 6: a filter that matches nothing says so, with what exists, and exits non-zero;
bare integer times are read by magnitude; a backwards range is an error."""

import json

import pytest

import cclogfs
from cclogfs.cli import main

T0 = 1432235695_000_000_000  # 2015-05-21T19:14:55Z


@pytest.fixture
def store(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True) as s:
        s.put_window("/odom", [(T0 + i * 10**8, json.dumps({"i": i})) for i in range(20)])
    return str(tmp_path / "s")


@pytest.mark.parametrize("argv", [
    ["cat", "{s}", "--topic", "/gps"],
    ["cat", "{s}", "--start", "2001-01-01", "--end", "2001-01-02"],
    ["export", "{s}", "--topic", "/gps", "--mcap", "{t}/o.mcap"],
    ["export", "{s}", "--topic", "/gps", "--parquet", "{t}/lake"],
    ["play", "{s}", "--topic", "/gps", "--rate", "1000"],
])  # fmt: skip
def test_store_filters_matching_nothing_fail_naming_what_exists(store, tmp_path, capsys, argv):
    assert main([a.format(s=store, t=tmp_path) for a in argv]) == 1
    cap = capsys.readouterr()
    assert cap.out == ""
    assert "no message" in cap.err and "/odom (2015-05-21T19:14:55.000Z to 2015-05-21T19:14:56.900Z)" in cap.err
    assert not (tmp_path / "o.mcap").exists() and not (tmp_path / "lake").exists()


def test_bare_integer_seconds_from_date_work(store, capsys):
    # `date +%s` output: seconds, not nanoseconds.
    assert main(["cat", store, "--start", str(T0 // 10**9), "--end", str(T0 // 10**9 + 1)]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 11
    with pytest.raises(SystemExit):
        main(["cat", "--help"])
    assert "seconds below 1e11" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["cat", "play"])
def test_backwards_range_is_an_error(store, capsys, command):
    assert main([command, store, "--start", str(T0 + 10**9), "--end", str(T0)]) == 1
    assert "is after --end" in capsys.readouterr().err


def test_convert_and_record_of_a_missing_topic_fail_naming_the_topics(shared_data, tmp_path, capsys):
    bag = str(shared_data("tf_example.bag"))
    assert main(["convert", bag, "-o", str(tmp_path / "o.jsonl"), "--topic", "/nothing"]) == 1
    err = capsys.readouterr().err
    assert "no topic /nothing" in err and "/tf" in err and not (tmp_path / "o.jsonl").exists()
    assert main(["record", bag, "--store", str(tmp_path / "s"), "--topic", "/nothing"]) == 1
    assert "no topic /nothing" in capsys.readouterr().err
    src = tmp_path / "in.jsonl"
    src.write_text(json.dumps({"topic": "/a", "stamp_ns": 1, "msg": {}}) + "\n")
    assert main(["convert", str(src), "-o", str(tmp_path / "o.jsonl"), "--topic", "/b"]) == 1
    assert "it holds /a" in capsys.readouterr().err and not (tmp_path / "o.jsonl").exists()
    assert main(["record", str(src), "--store", str(tmp_path / "s2"), "--topic", "/b"]) == 1
    assert "it holds /a" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [
    ["cat", "{s}", "--topic", "/odom", "--topic", "/gps"],
    ["export", "{s}", "--topic", "/odom", "--topic", "/gps", "--mcap", "{t}/o.mcap"],
    ["export", "{s}", "--topic", "/gps", "--topic", "/odom", "--parquet", "{t}/lake"],
    ["play", "{s}", "--topic", "/odom", "--topic", "/gps", "--rate", "1000"],
])  # fmt: skip
def test_one_of_several_topics_missing_from_a_store_is_an_error(store, tmp_path, capsys, argv):
    """A misspelt --topic beside a right one gave the right one's messages, exit 0, and said
    nothing of the other (found by attack)."""
    assert main([a.format(s=store, t=tmp_path) for a in argv]) == 1
    cap = capsys.readouterr()
    assert cap.out == "" and "has no stream /gps; it holds /odom (" in cap.err
    assert not (tmp_path / "o.mcap").exists() and not (tmp_path / "lake").exists()


def test_one_of_several_topics_missing_from_a_source_is_an_error(shared_data, tmp_path, capsys):
    bag = str(shared_data("tf_example.bag"))
    assert main(["convert", bag, "-o", str(tmp_path / "o.jsonl"), "--topic", "/tf", "--topic", "/tff"]) == 1
    assert "has no topic /tff; it holds /tf, /tf_static" in capsys.readouterr().err
    assert main(["record", bag, "--store", str(tmp_path / "s"), "--topic", "/tf", "--topic", "/tff"]) == 1
    assert "has no topic /tff" in capsys.readouterr().err and not (tmp_path / "s").exists()
    # JSONL learns its topics by reading: convert leaves no output, record says so after the run.
    src = tmp_path / "in.jsonl"
    src.write_text("".join(json.dumps({"topic": "/a", "stamp_ns": i, "msg": {}}) + "\n" for i in range(3)))
    assert main(["convert", str(src), "-o", str(tmp_path / "o.jsonl"), "--topic", "/a", "--topic", "/b"]) == 1
    assert "yielded no topic /b; it holds /a" in capsys.readouterr().err and not (tmp_path / "o.jsonl").exists()
    assert main(["record", str(src), "--store", str(tmp_path / "s2"), "--topic", "/a", "--topic", "/b"]) == 1
    assert "has no message on /b; the other topics were recorded (3 messages kept)" in capsys.readouterr().err
