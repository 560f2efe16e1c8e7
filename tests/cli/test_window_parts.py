"""A logging window counts once wherever it is counted, however many records hold it:
`record`'s end summary, the run's end record, `info` (table and --json) and `export` say the
same number (`cclogfs.windowcount`), the records apart.

Before, each part of a smart window was a window: `record slamfail_long_passage.mcap --model
M --window-max-s 0.001` said 36 windows for its 4 (one part per cut), `export` 50 (the
summaries among them), and a window over several topics counted once per topic and part
(nav2_turtlebot: 24 for 1). A window whose stamps go back, stored as records each in time
order, was one window to `record` and two to `info` and `export` (nav2_turtlebot's /odom
with its halves swapped: 14 against 15)."""

import json
import math
import re

import pytest

from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line
from cclogfs.pipeline import read_topic
from cclogfs.store import open_store
from conftest import shared_data_file

PASSAGE = "long/slamfail_long_passage.mcap"
SAID = re.compile(r" in ([\d,]+) windows(?: \(stored as ([\d,]+) records)?")


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    d = tmp_path_factory.mktemp("m")
    assert main(["train", str(shared_data_file("long/slamfail_hospital.mcap")), "--out", str(d / "model")]) == 0
    return str(d / "model")


def record(capsys, *args) -> tuple[int, int]:
    """`cclog record ARGS`: the windows and records its end summary says."""
    capsys.readouterr()
    assert main(["record", *args]) == 0
    err = capsys.readouterr().err
    m = SAID.search(err)
    assert m, err
    windows = int(m.group(1).replace(",", ""))
    return windows, int((m.group(2) or m.group(1)).replace(",", ""))


def info(store, capsys) -> dict:
    capsys.readouterr()
    assert main(["info", store, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def exported(store, tmp_path, capsys, *args) -> str:
    capsys.readouterr()
    assert main(["export", store, "--mcap", str(tmp_path / "out.mcap"), "--force", *args]) == 0
    return capsys.readouterr().err.splitlines()[0]


def window_ids(store, stream=None) -> set:
    with open_store(store, readonly=True) as s:
        return {w.meta["window_id"] for w in s.query(stream) if "window_id" in w.meta}


def test_a_smart_windows_parts_count_once_everywhere(tmp_path, capsys, model):
    src = str(shared_data_file(PASSAGE))
    store = str(tmp_path / "cut")
    windows, records = record(capsys, src, "--store", store, "--model", model, "--window-max-s", "0.001")
    assert records > windows  # stored in parts: what this test is about
    # the same windows as a recording that never cut one, and as many as their ids
    assert record(capsys, src, "--store", str(tmp_path / "whole"), "--model", model, "--window-max-s", "1000")[0] \
        == windows == len(window_ids(store))
    got = info(store, capsys)
    (run,) = got["runs"]
    assert (run["windows"], run["records"]) == (windows, records)
    odom = got["streams"]["/odom"]
    assert (odom["windows"], odom["records"]) == (windows, records)
    assert main(["info", store]) == 0
    out = capsys.readouterr().out
    assert re.search(rf"^/odom +{windows} +", out, re.M), out
    assert f"/odom: its {windows} windows are stored as {records} records (a smart logging window is stored in " \
           "parts" in out, out
    summaries = got["streams"]["/cclog/summary"]["windows"]
    assert exported(store, tmp_path, capsys).startswith(
        f"exported {windows} windows (stored as {records} records: a smart logging window is stored in parts")
    assert f") and {summaries} summaries, " in exported(store, tmp_path, capsys)


def test_a_window_cut_to_a_range_counts_once(tmp_path, capsys, model):
    store = str(tmp_path / "s")
    record(capsys, str(shared_data_file(PASSAGE)), "--store", store, "--model", model, "--window-max-s", "0.001")
    with open_store(store, readonly=True) as s:
        parts = sorted((w.start_ns, w.end_ns, w.meta["window_id"]) for w in s.query("/odom"))
    wid = parts[0][2]
    mine = [p for p in parts if p[2] == wid]
    assert len(mine) > 2
    start, end = mine[1][0], mine[-1][1]  # all its parts but the first
    said = exported(store, tmp_path, capsys, "--topic", "/odom", "--start", f"{start}ns", "--end", f"{end}ns")
    assert said.startswith("exported 1 windows ("), said


def test_a_window_over_several_topics_counts_once(tmp_path, capsys):
    # a model of the first half of nav2_turtlebot's /odom flags a stretch of the second
    odom = read_topic(str(shared_data_file("nav2_turtlebot.mcap")), "/odom")
    half = tmp_path / "half.jsonl"
    half.write_text("".join(format_line("/odom", s, t) for s, t in odom[: len(odom) // 2]))
    assert main(["train", str(half), "--out", str(tmp_path / "m")]) == 0
    store = str(tmp_path / "s")
    windows, records = record(capsys, str(shared_data_file("nav2_turtlebot.mcap")), "--store", store, "--model",
                              str(tmp_path / "m"), "--window-max-s", "0.001")  # fmt: skip
    got = info(store, capsys)
    streams = {name: st for name, st in got["streams"].items() if name != "/cclog/summary"}
    assert len(streams) > 1 and windows == len(window_ids(store)) > 0
    assert got["runs"][0]["windows"] == windows and records == sum(st["records"] for st in streams.values())
    for name, st in streams.items():  # a window counts once in each stream it logged
        assert st["windows"] == len(window_ids(store, name)), name
    assert exported(store, tmp_path, capsys).startswith(f"exported {windows} windows (stored as {records} records")


def test_a_window_whose_stamps_go_back_counts_once(tmp_path, capsys):
    odom = read_topic(str(shared_data_file("nav2_turtlebot.mcap")), "/odom")
    half = len(odom) // 2
    src = tmp_path / "swapped.jsonl"
    src.write_text("".join(format_line("/odom", s, t) for s, t in odom[half:] + odom[:half]))
    store = str(tmp_path / "s")
    windows, records = record(capsys, str(src), "--store", store, "--window-max-s", "1000")
    # the chunks of 200 messages `record` cut (--chunk): one holds the stamps going back
    assert (windows, records) == (math.ceil(len(odom) / 200), math.ceil(len(odom) / 200) + 1)
    got = info(store, capsys)
    assert (got["runs"][0]["windows"], got["runs"][0]["records"]) == (windows, records)
    assert (got["streams"]["/odom"]["windows"], got["streams"]["/odom"]["records"]) == (windows, records)
    assert exported(store, tmp_path, capsys).startswith(
        f"exported {windows} windows (stored as {records} records: a window whose stamps go back is stored as "
        "records each in time order)")


def test_info_names_a_record_it_cannot_read_and_counts_it_alone(tmp_path, capsys):
    # info reads every record's meta to count windows: one failing its checksum (damage the
    # store did not know of) is named and counted as a window of its own, exit 3, not 0
    from helpers import SEG, flip, make_store

    recs = make_store(tmp_path / "s", n=6)
    seq, off, length = recs[1]
    flip(tmp_path / "s" / SEG, off + length - 5)
    assert main(["info", str(tmp_path / "s")]) == 3
    out = capsys.readouterr().out
    assert f"DAMAGE (its record counted above as a window alone; `cclog fsck` names it): {SEG} at offset {off} " \
           f"(seq {seq}): " in out, out
    assert main(["info", str(tmp_path / "s"), "--json"]) == 3
    got = json.loads(capsys.readouterr().out)
    assert len(got["unreadable"]) == 1 and sum(st["windows"] for st in got["streams"].values()) == 6


def test_an_end_record_written_before_records_were_counted_reads_as_written(tmp_path, capsys):
    # an older cclog counted each part of a smart window in `windows` and wrote no `records`
    import cclogfs
    from cclogfs.runs import begin_run

    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", [(1, "{}")], {"window_id": "w1", "part": 0})
        begin_run(store, "/old.mcap").end("done", messages_in=9, messages_kept=1, windows=36, summaries=14,
                                          topics_kept={"/odom": 1})  # fmt: skip
    (run,) = info(str(tmp_path / "s"), capsys)["runs"]
    assert run["windows"] == 36 and "records" not in run
    assert main(["info", str(tmp_path / "s")]) == 0
    assert " 36 (+14 summaries) " in capsys.readouterr().out
