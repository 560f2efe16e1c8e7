"""rosmsg: rosbridge JSON back into rosbags messages, the inverse of jsontext.ros."""

from __future__ import annotations

import pytest
from rosbags.highlevel import AnyReader

from cclogfs.errors import InvalidInputError
from cclogfs.jsontext.rostypes import ros1_typestore
from cclogfs.jsontext.ros import MessageConverter
from cclogfs.jsontext.rosmsg import from_json


def test_json_to_message_and_back_is_exact_for_cdr_and_ros1(shared_data):
    to_json = MessageConverter().to_json
    with AnyReader([shared_data("nav2_turtlebot.mcap")]) as reader:
        ts, ts1 = reader.typestore, ros1_typestore(reader.typestore)
        seen = {}
        for c, _, raw in reader.messages():
            if seen.setdefault(c.topic, 0) >= 20:
                continue
            seen[c.topic] += 1
            text = to_json(reader.deserialize(raw, c.msgtype))
            # CDR: the same message (not always the same bytes: a publisher's padding is not zeroed)
            cdr = ts.serialize_cdr(from_json(ts, c.msgtype, text), c.msgtype)
            assert to_json(ts.deserialize_cdr(cdr, c.msgtype)) == text
            # ROS 1: a header gains seq = 0, everything else round-trips
            ros1 = ts1.serialize_ros1(from_json(ts1, c.msgtype, text), c.msgtype)
            back = to_json(ts1.deserialize_ros1(ros1, c.msgtype))
            assert back.replace('"seq": 0, ', "") == text
    assert set(seen) == {"/odom", "/tf", "/tf_static", "/amcl_pose"}


def test_bad_json_is_named_by_field():
    ts = ros1_typestore()
    t = "geometry_msgs/msg/PoseWithCovariance"
    with pytest.raises(InvalidInputError, match="has no field 'bogus'"):
        from_json(ts, t, '{"bogus": 1}')
    with pytest.raises(InvalidInputError, match=r"\.covariance: expected 36 elements, got 2"):
        from_json(ts, t, '{"covariance": [1, 2]}')
    with pytest.raises(InvalidInputError, match=r"pose\.position\.x: 'a' is not a float64"):
        from_json(ts, t, '{"pose": {"position": {"x": "a"}}}')
    with pytest.raises(InvalidInputError, match="not known"):
        from_json(ts, "nope/msg/Nope", "{}")
    zero = from_json(ts, t, "{}")  # missing fields are zero
    assert zero.pose.position.x == 0.0 and len(zero.covariance) == 36
