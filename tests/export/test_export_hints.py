"""A stored message its ROS 2 type cannot take stops an export with one line naming the
stream, message and field, and a fix the command takes. The rosbag2 export said "export it
as JSON with --encoding json", which `export --rosbag2` refuses ("--encoding is for
--mcap"): a bag is all CDR, so the fix is an MCAP export as JSON."""

import json

import pytest

from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line
from cclogfs.pipeline import read_topic
from conftest import shared_data_file


@pytest.fixture(scope="module")
def odd_store(tmp_path_factory):
    """nav2_turtlebot's /odom typed nav_msgs/msg/Odometry, message 32 with a number for
    child_frame_id (a string in the type)."""
    d = tmp_path_factory.mktemp("odd")
    lines = []
    for i, (stamp, text) in enumerate(read_topic(str(shared_data_file("nav2_turtlebot.mcap")), "/odom")):
        m = json.loads(text)
        if i == 32:
            m["child_frame_id"] = 7
        line = json.loads(format_line("/odom", stamp, json.dumps(m)))
        lines.append(json.dumps({**line, "msgtype": "nav_msgs/msg/Odometry"}) + "\n")
    (d / "odd.jsonl").write_text("".join(lines))
    assert main(["record", str(d / "odd.jsonl"), "--store", str(d / "s")]) == 0
    return d / "s"


@pytest.mark.parametrize("to", ["--mcap", "--rosbag2"])
def test_the_hint_names_a_fix_the_export_takes(odd_store, tmp_path, capsys, to):
    out = tmp_path / ("o.mcap" if to == "--mcap" else "bag")
    capsys.readouterr()
    assert main(["export", str(odd_store), to, str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "/odom, message 32 (log time" in err, err
    assert "nav_msgs/msg/Odometry.child_frame_id: expected a string" in err and not out.exists(), err
    fix = ["--mcap", str(tmp_path / "fixed.mcap"), "--encoding", "json"]
    if to == "--mcap":
        assert "export it as JSON with --encoding json" in err
    else:
        assert "export it to MCAP as JSON (--mcap OUT.mcap --encoding json)" in err, err
        assert main(["export", str(odd_store), to, str(out), "--encoding", "json"]) == 1  # what it said before
        assert "--encoding is for --mcap" in capsys.readouterr().err
    assert main(["export", str(odd_store), *fix]) == 0  # following the hint
