"""Issue 12 item 2: one clock (the log time) for every topic by default, so smart logging
of nav2_turtlebot.mcap (/odom in simulation time, /tf in wall time) keeps /tf and
/amcl_pose in the windows around /odom anomalies, and exports span the run, not 56 years."""

import json

import pytest
from mcap.reader import make_reader

import cclogfs
from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line
from cclogfs.pipeline import read_topic
from cclogfs.runs import hidden_by_default


@pytest.fixture
def recorded(shared_data, tmp_path):
    bag = str(shared_data("nav2_turtlebot.mcap"))
    odom = read_topic(bag, "/odom")
    # A model of the robot's first 40 s: the rest of the drive holds motion it never saw.
    train = tmp_path / "train.jsonl"
    train.write_text("".join(format_line("/odom", s, t) for s, t in odom[:400]))
    assert main(["train", str(train), "--out", str(tmp_path / "m")]) == 0
    assert main(["record", bag, "--store", str(tmp_path / "s"), "--model", str(tmp_path / "m"), "--force-model",
                 "--topic", "/tf", "--topic", "/amcl_pose"]) == 0  # fmt: skip
    return tmp_path


def test_smart_windows_hold_every_topic_and_exports_carry_log_times(recorded, capsys):
    with cclogfs.open_store(recorded / "s", readonly=True) as store:
        streams = store.streams()
        odom_windows = list(store.query("/odom"))
        assert odom_windows, "the model must open windows, or this test proves nothing"
        for name in ("/odom", "/tf", "/amcl_pose"):
            assert streams[name]["messages"] > 0, name
        # The header stamp stays in the message: /odom's JSON still says 928 s (simulation time).
        stamp, text = next(iter(odom_windows[0].messages()))
        assert json.loads(text)["header"]["stamp"]["sec"] < 10**4 and stamp > 1.7e18
        # The messages' windows; the runs' records (/cclog/runs) are stamped in wall-clock time.
        spans = [(w.start_ns, w.end_ns) for w in store.query() if not hidden_by_default(w.name)]
    assert max(e for _, e in spans) - min(s for s, _ in spans) < 3600 * 10**9
    assert main(["export", str(recorded / "s"), "--mcap", str(recorded / "o.mcap")]) == 0
    with open(recorded / "o.mcap", "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert stats.message_end_time - stats.message_start_time < 3600 * 10**9  # not 56 years
    assert main(["export", str(recorded / "s"), "--parquet", str(recorded / "lake"), "--robot", "r"]) == 0
    dates = {p.name for p in (recorded / "lake").glob("robot=r/*/date=*")}
    assert dates == {"date=2026-05-08"}


def test_clock_header_keeps_header_stamps(shared_data, tmp_path, capsys):
    bag = str(shared_data("nav2_turtlebot.mcap"))
    assert main(["convert", bag, "-o", str(tmp_path / "h.jsonl"), "--topic", "/odom", "--clock", "header"]) == 0
    assert json.loads(open(tmp_path / "h.jsonl").readline())["stamp_ns"] == 928_800_000_000
    assert main(["convert", bag, "-o", str(tmp_path / "l.jsonl"), "--topic", "/odom"]) == 0
    assert json.loads(open(tmp_path / "l.jsonl").readline())["stamp_ns"] == 1778234353382747000
