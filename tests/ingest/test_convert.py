"""jsontext.ros's generated converter gives the rosbridge spelling, checked against a plain
recursive reference on every message of the shared data and of simulated bags."""

import base64
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from cclogfs.jsontext.ros import MessageConverter, message_to_json


def reference(value, typestore):
    """The obvious, uncached conversion the converter must agree with: the fields the
    message definition in the typestore names (not its constants), in its order."""
    if dataclasses.is_dataclass(value):
        _, fields = typestore.fielddefs[value.__msgtype__]
        return {name: reference(getattr(value, name), typestore) for name, _ in fields}
    if isinstance(value, np.ndarray):
        if value.dtype in (np.uint8, np.int8):
            return base64.b64encode(value.tobytes()).decode("ascii")
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [reference(v, typestore) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _bags(shared_data, tmp_path_factory) -> list[Path]:
    from cclogfs.sim import simulate

    sim = tmp_path_factory.mktemp("sim")
    simulate(seed=3, duration_s=20, rate_hz=50, anomalies=2).write(sim, imu=True, tf=True)
    long = sorted(Path(shared_data("nav2_turtlebot.mcap")).parent.glob("long/*.mcap"))
    return [shared_data(n) for n in ("nav2_turtlebot.mcap", "tf_example.bag", "tf_example")] + long + [sim / "run"]


def test_every_shared_and_simulated_message(shared_data, tmp_path_factory):
    for path in _bags(shared_data, tmp_path_factory):
        conv = MessageConverter()
        with AnyReader([path]) as reader:
            for con, _, raw in reader.messages():
                msg = reader.deserialize(raw, con.msgtype)
                text = conv.to_json(msg)
                assert text == json.dumps(reference(msg, reader.typestore)) == message_to_json(msg), (path, con.topic)


@pytest.mark.parametrize("msgtype", ["sensor_msgs/msg/NavSatFix", "sensor_msgs/msg/NavSatStatus",
                                     "visualization_msgs/msg/Marker", "sensor_msgs/msg/Imu"])
def test_constants_are_not_fields(msgtype):
    """rosbridge leaves a definition's constants (NavSatStatus.STATUS_NO_FIX = -1) out."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    consts, fields = store.fielddefs[msgtype]
    msg = _default(store, msgtype)
    got = json.loads(MessageConverter().to_json(msg))
    assert list(got) == [name for name, _ in fields]
    text = message_to_json(msg)
    assert not any(f'"{name}"' in text for name, *_ in consts)
    if msgtype == "sensor_msgs/msg/NavSatFix":
        assert '"STATUS_NO_FIX"' not in text  # a constant of its status field


def _default(store, msgtype):
    """A message of msgtype with zero values (rosbags classes take every field by keyword)."""
    cls = store.types[msgtype]
    _, fields = store.fielddefs[msgtype]
    kwargs = {}
    for name, (node, detail) in fields:
        if node == 1:  # a base type
            kwargs[name] = "" if detail[0] == "string" else (False if detail[0] == "bool" else 0)
        elif node == 2:  # a nested message
            kwargs[name] = _default(store, detail)
        elif node == 3 and detail[0][0] == 1:  # a fixed-size array of a base type
            kwargs[name] = np.zeros(detail[1], dtype=np.float64 if detail[0][1][0].startswith("float") else np.int64)
        else:
            kwargs[name] = [] if detail[0][0] != 1 or detail[0][1][0] in ("string",) else np.zeros(0)
    return cls(**kwargs)


def test_byte_arrays_are_base64():
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    UInt8MultiArray = store.types["std_msgs/msg/UInt8MultiArray"]
    Layout = store.types["std_msgs/msg/MultiArrayLayout"]
    msg = UInt8MultiArray(layout=Layout(dim=[], data_offset=0), data=np.array([1, 2, 255], dtype=np.uint8))
    assert '"data": "AQL/"' in MessageConverter().to_json(msg)
