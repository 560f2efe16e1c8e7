"""jsontext.roswire: rosbridge JSON straight from ROS 1 / CDR bytes is byte for byte what
rosbags' objects through ros.MessageConverter give, on every shared bag and MCAP file, on
random messages of every type rosbags ships, and on damaged bytes (refused exactly when
rosbags refuses them, naming the field)."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

from cclogfs.jsontext.ros import MessageConverter, message_stamp_ns
from cclogfs.jsontext.roswire import ArrayMemo, WireError, WireFormatter, formatter_source, main, number_texts, numbers
from cclogfs.jsontext.roswire_gen import MARKER, _TypeTable

SAMPLE = 1500  # messages per file, evenly spread (the long files hold up to 22,692)


def _files(shared_data) -> list[Path]:
    data = Path(shared_data("nav2_turtlebot.mcap")).parent
    return [data / "nav2_turtlebot.mcap", data / "tf_example.bag", data / "tf_example", *sorted(data.glob("long/*.mcap"))]


def _same_as_rosbags(path: Path) -> int:
    """Compare both paths on (a sample of) every message of `path`; the count compared."""
    with AnyReader([path]) as reader:
        wire, conv = WireFormatter(reader.typestore, cdr=reader.is2), MessageConverter()
        every = max(1, sum(c.msgcount for c in reader.connections) // SAMPLE)
        n = 0
        for i, (con, _, raw) in enumerate(reader.messages()):
            if i % every:
                continue
            msg = reader.deserialize(raw, con.msgtype)
            assert wire.get(con.msgtype)(raw) == (conv.to_json(msg), message_stamp_ns(msg)), (path, con.topic, i)
            n += 1
    return n


def test_every_shared_file(shared_data):
    counts = {p.name: _same_as_rosbags(p) for p in _files(shared_data)}
    assert counts["tf_example.bag"] == counts["tf_example"] == 518 and min(counts.values()) >= 500


def test_simulated_ros1_and_ros2_bags(tmp_path):
    """Odometry, Imu and TF in a ROS 1 bag (the speed benchmark's) and a ROS 2 MCAP bag."""
    from bench.speed import write_ros1_bag
    from cclogfs.sim import simulate

    assert write_ros1_bag(tmp_path / "sim.bag", 0.05) == 600
    simulate(seed=3, duration_s=6, rate_hz=50, anomalies=0).write(tmp_path / "ros2", imu=True, tf=True)
    assert _same_as_rosbags(tmp_path / "sim.bag") == 600
    assert _same_as_rosbags(tmp_path / "ros2" / "run") > 600


# -- random messages of every type of rosbags' stores ------------------------------------

STORES = {"ros1": get_typestore(Stores.ROS1_NOETIC), "cdr": get_typestore(Stores.ROS2_HUMBLE)}
FORMATTERS = {"ros1": WireFormatter(STORES["ros1"], cdr=False), "cdr": WireFormatter(STORES["cdr"], cdr=True)}
INT_RANGES = {"byte": 8, "int8": 8, "int16": 16, "int32": 32, "int64": 64}  # signed bits; unsigned below
UINT_BITS = {"char": 8, "uint8": 8, "uint16": 16, "uint32": 32, "uint64": 64}
DTYPES = {"bool": np.bool_, "byte": np.int8, "char": np.uint8, "float32": np.float32, "float64": np.float64}


def _base(typ: str) -> st.SearchStrategy:
    if typ == "string":
        return st.text(max_size=6)
    if typ == "bool":
        return st.booleans()
    if typ == "float32":
        return st.floats(width=32)
    if typ == "float64":
        return st.floats()
    if typ in INT_RANGES:
        bits = INT_RANGES[typ]
        return st.integers(-(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return st.integers(0, 2 ** UINT_BITS[typ] - 1)


def _values(store, desc, size: st.SearchStrategy) -> st.SearchStrategy:
    """A list strategy (numpy array for numbers, as rosbags serializes them)."""
    node, detail = desc
    if node == Nodetype.NAME:
        return st.lists(_message(store, detail), min_size=size, max_size=size) if isinstance(size, int) else \
            size.flatmap(lambda n: st.lists(_message(store, detail), min_size=n, max_size=n))  # fmt: skip
    typ = detail[0]
    dtype = DTYPES.get(typ, getattr(np, typ, None))
    lists = st.lists(_base(typ), min_size=size, max_size=size) if isinstance(size, int) else \
        size.flatmap(lambda n: st.lists(_base(typ), min_size=n, max_size=n))  # fmt: skip
    return lists if typ == "string" else lists.map(lambda v: np.array(v, dtype=dtype))


def _field(store, desc) -> st.SearchStrategy:
    node, detail = desc
    if node == Nodetype.BASE:
        return _base(detail[0])
    if node == Nodetype.NAME:
        return _message(store, detail)
    if node == Nodetype.ARRAY:
        return _values(store, detail[0], detail[1])
    bound = detail[1] or 3
    return _values(store, detail[0], st.integers(0, min(bound, 3)))


def _message(store, msgtype: str) -> st.SearchStrategy:
    msgdef = store.get_msgdef(msgtype)
    return st.builds(msgdef.cls, **{name: st.deferred(lambda d=desc: _field(store, d))
                                    for name, desc in msgdef.fields if name != MARKER})  # fmt: skip


@st.composite
def serialized(draw, wire: str):
    """(wire, type, bytes) of a random message of a random type of the store."""
    store = STORES[wire]
    msgtype = draw(st.sampled_from(sorted(store.fielddefs)))
    msg = draw(_message(store, msgtype))
    if wire == "ros1":
        raw = store.serialize_ros1(msg, msgtype)
    else:
        raw = store.serialize_cdr(msg, msgtype, little_endian=draw(st.booleans()))
    return wire, msgtype, bytes(raw)


def _reference(wire: str, msgtype: str, raw: bytes):
    """rosbags + MessageConverter: (text, stamp), or None when rosbags refuses the bytes."""
    store = STORES[wire]
    try:
        msg = store.deserialize_ros1(raw, msgtype) if wire == "ros1" else store.deserialize_cdr(raw, msgtype)
    except Exception:  # noqa: BLE001 - any refusal
        return None
    return MessageConverter().to_json(msg), message_stamp_ns(msg)


def _formatted(wire: str, msgtype: str, raw: bytes):
    try:
        return FORMATTERS[wire].get(msgtype)(raw)
    except WireError:
        return None


SLOW = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def test_every_type_of_rosbags_stores_has_a_formatter():
    for wire, formatter in FORMATTERS.items():
        assert [t for t in sorted(STORES[wire].fielddefs) if formatter.get(t) is None] == [], wire


def test_the_generator_reads_the_fields_rosbags_reads():
    """The generator reads `fielddefs` itself (rosbags' get_msgdef compiles serializers it
    does not need); the fields and classes must be get_msgdef's, for every type."""
    for store in STORES.values():
        table = _TypeTable(store)
        for msgtype in store.fielddefs:
            ours, theirs = table.get_msgdef(msgtype), store.get_msgdef(msgtype)
            assert (ours.fields, ours.cls) == (theirs.fields, theirs.cls), msgtype


@SLOW
@given(serialized("ros1"))
def test_random_ros1_messages(case):
    wire, msgtype, raw = case
    assert _formatted(wire, msgtype, raw) == _reference(wire, msgtype, raw) is not None


@SLOW
@given(serialized("cdr"))
def test_random_cdr_messages(case):
    wire, msgtype, raw = case
    assert _formatted(wire, msgtype, raw) == _reference(wire, msgtype, raw) is not None


@SLOW
@given(st.sampled_from(["ros1", "cdr"]).flatmap(serialized), st.data())
def test_damaged_bytes_are_refused_exactly_when_rosbags_refuses_them(case, data):
    """Cut, flipped, grown: either both paths refuse the bytes, or both give the same text."""
    wire, msgtype, raw = case
    how = data.draw(st.sampled_from(["cut", "flip", "grow"]))
    if how == "cut":
        raw = raw[: data.draw(st.integers(0, max(0, len(raw) - 1)))]
    elif how == "flip" and raw:
        i = data.draw(st.integers(0, len(raw) - 1))
        raw = raw[:i] + bytes([raw[i] ^ data.draw(st.integers(1, 255))]) + raw[i + 1 :]
    else:
        raw += data.draw(st.binary(min_size=1, max_size=9))
    assert _formatted(wire, msgtype, raw) == _reference(wire, msgtype, raw)


# -- errors, floats, the memo, the source text ---------------------------------------------

def _odometry(store, **pose):
    T = store.types
    header = T["std_msgs/msg/Header"](seq=7, stamp=T["builtin_interfaces/msg/Time"](sec=5, nanosec=6), frame_id="odom")
    point = T["geometry_msgs/msg/Point"](**{"x": 0.0, "y": 0.0, "z": 0.0, **pose})
    pose = T["geometry_msgs/msg/Pose"](position=point, orientation=T["geometry_msgs/msg/Quaternion"](x=0, y=0, z=0, w=1))
    twist = T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
                                         angular=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0))  # fmt: skip
    return T["nav_msgs/msg/Odometry"](header=header, child_frame_id="base_link",
                                      pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                                      twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))  # fmt: skip


def test_nan_infinities_and_negative_zero_are_spelled_as_json_dumps_does():
    store, fmt = STORES["ros1"], FORMATTERS["ros1"].get("nav_msgs/msg/Odometry")
    msg = _odometry(store, x=math.nan, y=-math.inf, z=-0.0)
    msg.pose.covariance[:3] = [math.inf, -0.0, 1e-7]
    raw = bytes(store.serialize_ros1(msg, "nav_msgs/msg/Odometry"))
    text, stamp = fmt(raw)
    assert '"x": NaN, "y": -Infinity, "z": -0.0' in text and '"covariance": [Infinity, -0.0, 1e-07, 0.0' in text
    assert stamp == 5_000_000_006
    assert text == MessageConverter().to_json(store.deserialize_ros1(raw, "nav_msgs/msg/Odometry"))


NUMBERS = st.lists(st.floats() | st.floats(width=32) | st.integers(-(2**63), 2**64 - 1)
                   | st.sampled_from([1e-05, 9.9e-05, 1e-4, 1e16, 1e15 + 0.5, 5e-324, -0.0]), max_size=40)  # fmt: skip


@given(NUMBERS)
def test_numbers_are_rendered_as_json_dumps_renders_them(values):
    """orjson writes the numbers; the tokens it may write otherwise (exponents, NaN, the
    decade below 1e-4) are rendered again: every text is json.dumps'."""
    if values:  # generated code calls it with the numbers of a message, never none
        assert number_texts(tuple(values)) == [json.dumps(v) for v in values]
    assert numbers(tuple(values)) == json.dumps(values)


def test_the_memo_tells_arrays_apart_by_their_bytes_and_stops_when_they_keep_changing():
    memo = ArrayMemo(struct.Struct("<3d").unpack)
    zero, negative = struct.pack("<3d", 0.0, 0.0, 0.0), struct.pack("<3d", -0.0, 0.0, 0.0)
    assert [memo.text(zero), memo.text(negative), memo.text(zero)] == ["[0.0, 0.0, 0.0]", "[-0.0, 0.0, 0.0]"] + ["[0.0, 0.0, 0.0]"]
    assert memo.hits == 1
    for i in range(ArrayMemo.LIMIT):  # every array new: no use remembering them
        assert memo.text(struct.pack("<3d", i, math.nan, 0.5)) == f"[{float(i)!r}, NaN, 0.5]"
    assert not memo.on and memo.text(zero) == "[0.0, 0.0, 0.0]"


def test_errors_name_the_field():
    from cclogfs.jsontext.rostypes import ros1_typestore

    store = ros1_typestore(STORES["cdr"])  # Noetic has no tf2_msgs: ROS 2's, with ROS 1 headers
    fmt = WireFormatter(store, cdr=False).get("tf2_msgs/msg/TFMessage")
    T = store.types
    tf = T["geometry_msgs/msg/TransformStamped"](
        header=T["std_msgs/msg/Header"](seq=1, stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="map"),
        child_frame_id="odom", transform=T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=1, y=2, z=3),
            rotation=T["geometry_msgs/msg/Quaternion"](x=0, y=0, z=0, w=1)))  # fmt: skip
    raw = bytes(store.serialize_ros1(T["tf2_msgs/msg/TFMessage"](transforms=[tf, tf]), "tf2_msgs/msg/TFMessage"))
    assert json.loads(fmt(raw)[0])["transforms"][1]["child_frame_id"] == "odom"
    second = raw.index(b"map", raw.index(b"map") + 1) - 4  # the length of the second frame_id
    bad = raw[:second] + struct.pack("<I", 999) + raw[second + 4 :]
    with pytest.raises(WireError, match=r"field transforms\[1\]\.header\.frame_id: invalid string length 999"):
        fmt(bad)
    with pytest.raises(WireError, match=r"field transforms\[1\]\.transform\.translation\.x \.\. "):
        fmt(raw[:-20])
    with pytest.raises(WireError, match="1 bytes left over"):
        fmt(raw + b"\0")
    bad_utf8 = raw.replace(b"odom", b"od\xffm", 1)
    with pytest.raises(WireError, match=r"field transforms\[0\]\.child_frame_id: .*utf-8"):
        fmt(bad_utf8)
    with pytest.raises(WireError, match="CDR encapsulation"):
        FORMATTERS["cdr"].get("tf2_msgs/msg/TFMessage")(b"\x02\x00\x00\x00")


def test_the_generated_source_can_be_read(shared_data, capsys):
    source = formatter_source(STORES["ros1"], "nav_msgs/msg/Odometry")
    assert "def message(raw):" in source and '"frame_id": {s2}' in source and "memo_" in source
    compile(source, "odometry", "exec")
    assert main([str(shared_data("tf_example.bag")), "tf2_msgs/msg/TFMessage"]) == 0
    out = capsys.readouterr().out
    assert "def f_geometry_msgs__msg__TransformStamped(raw, pos):" in out and "messages(" in out
