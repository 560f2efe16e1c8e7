import json

from rosbags.highlevel import AnyReader

from cclogfs.jsontext.ros import message_stamp_ns, message_to_json


def test_odometry_json_shape(shared_data):
    path = shared_data("nav2_turtlebot.mcap")
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == "/odom"]
        con, logtime, raw = next(reader.messages(connections=conns))
        msg = reader.deserialize(raw, con.msgtype)
    text = message_to_json(msg)
    obj = json.loads(text)
    assert list(obj) == ["header", "child_frame_id", "pose", "twist"]
    assert obj["header"]["stamp"] == {"sec": 928, "nanosec": 800000000}
    assert len(obj["pose"]["covariance"]) == 36
    assert message_stamp_ns(msg) == 928_800_000_000
    assert json.dumps(obj) == text
