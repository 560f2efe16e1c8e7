"""`cclog cat` and `cclog export` over a real store."""

from __future__ import annotations

import datetime as dt
import json

import duckdb
from _windows import fill_store, read_topics
from mcap.reader import make_reader

from cclogfs.cli import main


def test_convert_store_cat_byte_exact(shared_data, tmp_path, capsys):
    converted = tmp_path / "odom.jsonl"
    assert main(["convert", str(shared_data("nav2_turtlebot.mcap")), "-o", str(converted),
                 "--topic", "/odom"]) == 0  # fmt: skip
    store = fill_store(tmp_path / "store", read_topics(converted, ["/odom"]))
    capsys.readouterr()
    assert main(["cat", str(store)]) == 0
    assert capsys.readouterr().out == converted.read_text()

    # --start/--end clip messages, given as seconds, ns or ISO-8601 alike.
    lines = converted.read_text().splitlines(True)
    stamps = [json.loads(line)["stamp_ns"] for line in lines]
    lo, hi = stamps[150], stamps[420]
    day = dt.datetime.fromtimestamp(lo // 10**9, dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")
    iso = f"{day}.{lo % 10**9:09d}Z"
    for start, end in [(f"{lo / 1e9:.3f}", str(hi)), (iso, f"{hi}ns"), (iso[:-1] + "+00:00", f"{hi / 1e9}s")]:
        assert main(["cat", str(store), "--topic", "/odom", "--start", start, "--end", end]) == 0
        out = capsys.readouterr().out
        assert out == "".join(lines[150:421])
    assert main(["cat", str(store), "--topic", "/nothing"]) == 1  # said, not silent (issue 12)
    assert capsys.readouterr().out == ""


def test_multi_topic_cat_is_time_ordered(shared_data, tmp_path, capsys):
    data = read_topics(shared_data("nav2_turtlebot.mcap"), ["/odom", "/amcl_pose"])
    store = fill_store(tmp_path / "store", data)
    assert main(["cat", str(store), "--topic", "/odom", "--topic", "/amcl_pose"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert len(rows) == 2639 + 135
    assert [r["stamp_ns"] for r in rows] == sorted(r["stamp_ns"] for r in rows)


def test_export_commands(shared_data, tmp_path, capsys):
    data = read_topics(shared_data("nav2_turtlebot.mcap"), ["/odom", "/amcl_pose"])
    store = fill_store(tmp_path / "tb3", data)
    out = tmp_path / "x.mcap"
    assert main(["export", str(store), "--mcap", str(out), "--topic", "/amcl_pose"]) == 0
    assert "exported 2 windows, 135 messages of 1 streams" in capsys.readouterr().err
    with open(out, "rb") as f:
        texts = [m.data.decode() for _, _, m in make_reader(f).iter_messages()]
    assert texts == [t for _, t in data["/amcl_pose"]]

    lake = tmp_path / "lake"
    assert main(["export", str(store), "--parquet", str(lake)]) == 0
    assert main(["export", str(store), "--parquet", str(lake)]) == 1  # already there
    assert "already holds an export for robot 'tb3'" in capsys.readouterr().err
    assert main(["export", str(store), "--parquet", str(lake), "--replace"]) == 0
    counts = duckdb.sql(
        f"SELECT robot, stream, count(*) FROM read_parquet('{lake}/**/*.parquet', "
        "hive_partitioning=true, union_by_name=true) GROUP BY ALL ORDER BY ALL"
    ).fetchall()
    assert counts == [("tb3", "/amcl_pose", 135), ("tb3", "/odom", 2639)]


def test_export_start_end_exports_what_cat_prints(shared_data, tmp_path, capsys):
    """Export took whole windows for --start/--end (up to a window's worth of messages
    either side, unsaid in its summary) where `cat` prints the range exactly: now both
    give the same messages, and the summary says how many outside the range were left out."""
    data = read_topics(shared_data("nav2_turtlebot.mcap"), ["/odom", "/amcl_pose"])
    store = fill_store(tmp_path / "tb3", data)
    stamps = [s for s, _ in data["/odom"]]
    lo, hi = stamps[150], stamps[420]  # inside windows, not at their ends
    rng = ["--start", f"{lo}ns", "--end", f"{hi}ns"]
    capsys.readouterr()
    assert main(["cat", str(store), *rng]) == 0
    want = sorted((json.loads(line)["topic"], json.loads(line)["stamp_ns"]) for line in capsys.readouterr().out.splitlines())
    assert min(s for _, s in want) == lo and max(s for _, s in want) == hi
    out = tmp_path / "x.mcap"
    assert main(["export", str(store), "--mcap", str(out), *rng]) == 0
    err = capsys.readouterr().err
    with open(out, "rb") as f:
        got = sorted((c.topic, m.log_time) for _, c, m in make_reader(f).iter_messages())
    assert got == want
    in_windows = sum(1 for name in data for s, _ in data[name] if s < lo or s > hi)  # upper bound
    assert "cut to --start/--end: " in err and f", {len(want)} messages of 2 streams" in err, err
    left_out = int(err.split("cut to --start/--end: ")[1].split(" messages")[0].replace(",", ""))
    assert 0 < left_out < in_windows
    lake = tmp_path / "lake"
    assert main(["export", str(store), "--parquet", str(lake), *rng]) == 0
    n = duckdb.sql(f"SELECT count(*) FROM read_parquet('{lake}/**/*.parquet', union_by_name=true)").fetchall()[0][0]
    assert n == len(want)
