"""LiveSource: serialized messages from a running node give the same JSON as the bag."""

from __future__ import annotations

import sys
import threading
import time
import types

import pytest
from rosbags.highlevel import AnyReader

from cclogfs.errors import InvalidInputError, SourceError
from cclogfs.ingest import JsonlSource, open_source
from cclogfs.ingest.live import JsonlSink, LiveSource, ros2_msgtype


def raw_messages(path, topics):
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        return [(c.topic, c.msgtype, t, raw) for c, t, raw in reader.messages(connections=conns)]


def test_cdr_feed_matches_bag_reading(shared_data):
    path = shared_data("nav2_turtlebot.mcap")
    topics = {"/odom", "/amcl_pose", "/tf"}
    got = []
    live = LiveSource(got.append)
    for topic, msgtype, logtime, raw in raw_messages(path, topics):
        live.feed_cdr(topic, msgtype, raw, recv_ns=logtime)
    with open_source(path, topics) as src:
        assert got == list(src)
    assert live.count == 2639 + 135 + 5422


def test_message_objects_and_clock(shared_data, tmp_path):
    path = shared_data("tf_example.bag")
    with AnyReader([path]) as reader:
        msgs = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
    out = tmp_path / "live.jsonl"
    sink = JsonlSink(out, flush_every=7)
    live = LiveSource(sink, clock_ns=lambda: 42)
    items = [live.feed(topic, msg) for topic, msg in msgs]  # TFMessage: no header
    sink.close()
    assert {m.stamp_ns for m in items} == {42}
    assert [(m.topic, m.text) for m in JsonlSource(out)] == [(m.topic, m.text) for m in items]
    with open_source(path) as src:
        assert [m.text for m in items] == [m.text for m in src]


def test_rclpy_objects_are_serialized_with_rclpy(shared_data, monkeypatch):
    # Stand in for rclpy (not installed here): its serializer yields the CDR bytes.
    path = shared_data("nav2_turtlebot.mcap")
    topic, msgtype, logtime, raw = raw_messages(path, {"/odom"})[0]
    Odometry = type("Odometry", (), {"__module__": "nav_msgs.msg._odometry"})
    fake = types.ModuleType("rclpy.serialization")
    fake.serialize_message = lambda msg: raw
    monkeypatch.setitem(sys.modules, "rclpy", types.ModuleType("rclpy"))
    monkeypatch.setitem(sys.modules, "rclpy.serialization", fake)
    assert LiveSource(lambda m: None).feed("/odom", Odometry(), recv_ns=1).stamp_ns == 1  # the log time
    got = LiveSource(lambda m: None, clock="header").feed("/odom", Odometry(), recv_ns=1)
    assert got.msgtype == "nav_msgs/msg/Odometry" and got.stamp_ns == 928_800_000_000
    with open_source(path, ["/odom"]) as src:
        assert got.text == next(iter(src)).text


def test_unknown_types_and_bad_data():
    live = LiveSource(lambda m: None)
    with pytest.raises(SourceError, match=r"'acme_msgs/msg/Gripper' on /grip is unknown"):
        live.feed_cdr("/grip", "acme_msgs/msg/Gripper", b"\x00\x01\x00\x00" + bytes(8))
    live.add_type("acme_msgs/msg/Gripper", "float64 width\nbool closed\n")
    item = live.feed_cdr("/grip", "acme_msgs/msg/Gripper", b"\x00\x01\x00\x00" + bytes(8) + b"\x01",
                         recv_ns=5)  # fmt: skip
    assert (item.text, item.stamp_ns) == ('{"width": 0.0, "closed": true}', 5)
    with pytest.raises(SourceError, match=r"Cannot decode the nav_msgs/msg/Odometry message on /odom"):
        live.feed_cdr("/odom", "nav_msgs/msg/Odometry", b"\x00\x01\x00\x00\x01")
    with pytest.raises(InvalidInputError, match=r"not a ROS 2 message class"):
        ros2_msgtype(dict)


def test_sink_calls_are_serialized(shared_data):
    raws = raw_messages(shared_data("nav2_turtlebot.mcap"), {"/odom"})[:200]
    inside = []
    overlaps = []

    def sink(m):
        inside.append(1)
        time.sleep(0.0002)  # give other threads the chance to enter, were there no lock
        overlaps.append(len(inside))
        inside.pop()

    live = LiveSource(sink)
    threads = [
        threading.Thread(target=lambda part=raws[i::4]: [live.feed_cdr(t, mt, r, lt) for t, mt, lt, r in part])
        for i in range(4)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert live.count == 200 and max(overlaps) == 1
