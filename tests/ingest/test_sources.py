"""Bag, MCAP and directory sources over the shared real data; file-type detection."""

from __future__ import annotations

import json
from collections import Counter

import pytest
from rosbags.highlevel import AnyReader

from cclogfs.errors import SourceError
from cclogfs.ingest import (
    FORMATS,
    Source,
    detect_format,
    open_source,
)
from cclogfs.jsontext.ros import message_to_json

BAGS = {
    "nav2_turtlebot.mcap": ("rosbag2", {"/odom": 2639, "/tf": 5422, "/tf_static": 1, "/amcl_pose": 135}),
    "tf_example.bag": ("rosbag1", {"/tf": 517, "/tf_static": 1}),
    "tf_example": ("rosbag2", {"/tf": 517, "/tf_static": 1}),
}


@pytest.mark.parametrize("name", sorted(BAGS))
def test_every_message_of_every_bag(shared_data, name):
    path = shared_data(name)
    fmt, counts = BAGS[name]
    assert detect_format(path) == fmt
    with open_source(path) as src:
        assert isinstance(src, Source)
        msgs = list(src)
    assert Counter(m.topic for m in msgs) == counts
    # The same texts and stamps as converting each message with jsontext.ros directly.
    with AnyReader([path]) as reader:
        expect = []
        for con, logtime, raw in reader.messages():
            msg = reader.deserialize(raw, con.msgtype)
            expect.append((con.topic, logtime, message_to_json(msg)))
    assert [(m.topic, m.stamp_ns, m.text) for m in msgs] == expect  # the log time (docs/JSON.md)


def test_topic_selection_and_header_stamps(shared_data):
    path = shared_data("nav2_turtlebot.mcap")
    with open_source(path, topics=["/odom", "/amcl_pose"]) as src:
        assert src.topics() == {
            "/odom": "nav_msgs/msg/Odometry",
            "/amcl_pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        }
        msgs = list(src)
    assert Counter(m.topic for m in msgs) == {"/odom": 2639, "/amcl_pose": 135}
    first = next(m for m in msgs if m.topic == "/odom")
    assert first.stamp_ns == 1778234353382747000  # the log time, by default (docs/JSON.md)
    assert first.msgtype == "nav_msgs/msg/Odometry"
    with open_source(path, topics=["/odom"], clock="header") as src:
        assert next(iter(src)).stamp_ns == 928_800_000_000  # header.stamp
    with open_source(path, topics=["/nothing"]) as src:
        assert list(src) == []


def test_messages_without_header_get_log_time(shared_data):
    path = shared_data("tf_example.bag")
    with open_source(path, topics=["/tf"]) as src:
        msgs = list(src)
    with AnyReader([path]) as reader:
        logtimes = [t for _, t, _ in reader.messages()]
    assert [m.stamp_ns for m in msgs] == logtimes[1:]  # the first message is /tf_static
    assert "seq" in json.loads(msgs[0].text)["transforms"][0]["header"]  # ROS 1 header


def test_ros1_and_ros2_bags_hold_the_same_transforms(shared_data):
    def transforms(name):
        with open_source(shared_data(name), topics=["/tf"]) as src:
            out = []
            for m in src:
                for t in json.loads(m.text)["transforms"]:
                    t["header"].pop("seq", None)
                    out.append(t)
            return out

    assert transforms("tf_example.bag") == transforms("tf_example")


def test_unknown_and_missing_inputs(tmp_path, shared_data):
    (tmp_path / "notes.txt").write_text("hello robot\n")
    with pytest.raises(SourceError, match=r"notes.txt is of an unknown file type"):
        open_source(tmp_path / "notes.txt")
    with pytest.raises(SourceError, match=r"missing.bag.*No such file"):
        open_source(tmp_path / "missing.bag")
    (tmp_path / "emptydir").mkdir()
    with pytest.raises(SourceError, match=r"emptydir is a directory without metadata.yaml"):
        open_source(tmp_path / "emptydir")
    (tmp_path / "trunc.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 20)
    with open_source(tmp_path / "trunc.mcap") as src:  # read as far as it can be (ingest.salvage)
        assert list(src) == [] and "trunc.mcap is damaged" in src.lost
    renamed = tmp_path / "tf_example.data"
    renamed.write_bytes(shared_data("tf_example.bag").read_bytes())
    with pytest.raises(SourceError, match=r"tf_example.data is a ROS 1 bag.*\.bag"):
        open_source(renamed)
    with pytest.raises(SourceError, match=r"Unknown source format 'csv'"):
        open_source(renamed, format="csv")


def test_formats_map_to_source_classes():
    assert set(FORMATS) == {"rosbag1", "rosbag2", "mcap-json", "jsonl"}
    assert all(hasattr(cls, "__iter__") and hasattr(cls, "topics") for cls in FORMATS.values())


def test_a_store_given_as_a_source_is_named_as_one(tmp_path, capsys):
    # It said "not a ROS 2 bag", which told nothing of what it is nor how to read it.
    import cclogfs
    from cclogfs.cli import main

    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/a", [(1, "{}")])
    assert main(["record", str(tmp_path / "s"), "--store", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a cclogfs store" in err
    assert f"cclog cat {tmp_path / 's'}" in err and "cclog export" in err
    assert not (tmp_path / "o").exists()
