"""jsontext.ros's cached converter gives the rosbridge spelling, checked against a plain
recursive reference on every message of the shared data."""

import base64
import dataclasses
import json

import numpy as np
from rosbags.highlevel import AnyReader

from cclogfs.jsontext.ros import MessageConverter, message_to_json


def reference(value):
    """The obvious, uncached conversion the converter must agree with."""
    if dataclasses.is_dataclass(value):
        return {f.name: reference(getattr(value, f.name)) for f in dataclasses.fields(value)
                if not f.name.startswith("__")}  # fmt: skip
    if isinstance(value, np.ndarray):
        if value.dtype in (np.uint8, np.int8):
            return base64.b64encode(value.tobytes()).decode("ascii")
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [reference(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def test_every_shared_message(shared_data):
    for name in ("nav2_turtlebot.mcap", "tf_example.bag", "tf_example"):
        conv = MessageConverter()
        with AnyReader([shared_data(name)]) as reader:
            for con, _, raw in reader.messages():
                msg = reader.deserialize(raw, con.msgtype)
                text = conv.to_json(msg)
                assert text == json.dumps(reference(msg)) == message_to_json(msg)


def test_byte_arrays_are_base64():
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    UInt8MultiArray = store.types["std_msgs/msg/UInt8MultiArray"]
    Layout = store.types["std_msgs/msg/MultiArrayLayout"]
    msg = UInt8MultiArray(layout=Layout(dim=[], data_offset=0), data=np.array([1, 2, 255], dtype=np.uint8))
    assert '"data": "AQL/"' in MessageConverter().to_json(msg)
