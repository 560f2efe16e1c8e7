"""cclogfs.ingest.rosbag: ROS 1 and ROS 2 bags (rosbags), messages as JSON text."""

from __future__ import annotations

import json
import struct

import pytest

from cclogfs.errors import SourceError
from cclogfs.ingest import RosbagSource


def test_damaged_bag_names_the_file(tmp_path, shared_data):
    data = shared_data("tf_example.bag").read_bytes()
    bad = tmp_path / "cut.bag"
    bad.write_bytes(data[: len(data) // 3])
    with pytest.raises(SourceError, match=r"cut.bag"):
        with RosbagSource(bad) as src:
            list(src)


@pytest.mark.parametrize("name", ["tf_example.bag", "tf_example"])
def test_topics_count_and_ros1_description(shared_data, name):
    with RosbagSource(shared_data(name)) as src:
        assert src.topics() == {"/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"}
        assert src.message_count == 518 == sum(1 for _ in src)
        d = src.describe("/tf")
        assert len(d["md5sum"]) == 32 and "geometry_msgs/TransformStamped[] transforms" in d["msgdef"]
        assert src.describe("/nothing") == {}


def test_topic_selection_in_the_source(shared_data):
    with RosbagSource(shared_data("tf_example.bag"), topics=["/tf_static"]) as src:
        assert [m.topic for m in src] == ["/tf_static"]


def test_a_file_that_is_no_bag_is_a_source_error(tmp_path):
    (tmp_path / "x.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    with pytest.raises(SourceError, match=r"x.bag"):
        with RosbagSource(tmp_path / "x.bag") as src:
            list(src)


# -- the fast paths: ros1chunks (reading) and jsontext.roswire (formatting) ------------------

def _odometry_bag(path, count: int, broken: dict[int, bytes] | None = None, chunk: int = 0):
    """A ROS 1 bag of `count` Odometry messages on /odom (stamps 1..count s); `broken` maps a
    message number (1-based) to bytes written in its place; `chunk`: chunks of that many bytes
    (about), lz4-compressed."""
    import numpy as np
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    T = store.types
    writer = Writer(path)
    if chunk:
        writer.set_compression(Writer.CompressionFormat.LZ4)
        writer.chunk_threshold = chunk
    with writer:
        conn = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        for i in range(1, count + 1):
            v3 = T["geometry_msgs/msg/Vector3"](x=i * 0.1, y=-0.0, z=0.0)
            msg = T["nav_msgs/msg/Odometry"](
                header=T["std_msgs/msg/Header"](seq=i, stamp=T["builtin_interfaces/msg/Time"](sec=100 + i, nanosec=5),
                                                frame_id="odom"),
                child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](
                    pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=i, y=0.5, z=0.0),
                                                     orientation=T["geometry_msgs/msg/Quaternion"](x=0, y=0, z=0, w=1)),
                    covariance=np.eye(6).ravel() * 1e-3),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=T["geometry_msgs/msg/Twist"](linear=v3, angular=v3),
                                                                 covariance=np.zeros(36)))  # fmt: skip
            raw = (broken or {}).get(i) or bytes(store.serialize_ros1(msg, "nav_msgs/msg/Odometry"))
            writer.write(conn, i * 1_000_000_000, raw)
    return path


def _rosbags_messages(path, clock="log"):
    """What RosbagSource gave before its fast paths: rosbags' reader, objects, MessageConverter."""
    from rosbags.highlevel import AnyReader

    from cclogfs.jsontext.ros import MessageConverter, message_stamp_ns

    conv = MessageConverter()
    with AnyReader([path]) as reader:
        out = []
        for con, logtime, raw in reader.messages():
            msg = reader.deserialize(raw, con.msgtype)
            stamp = message_stamp_ns(msg) if clock == "header" else 0
            out.append((con.topic, stamp or logtime, conv.to_json(msg), con.msgtype))
    return out


@pytest.mark.parametrize("clock", ["log", "header"])
def test_ros1_bag_messages_and_stamps_as_before(tmp_path, clock):
    bag = _odometry_bag(tmp_path / "odom.bag", 30)
    with RosbagSource(bag, clock=clock) as src:
        got = [tuple(m) for m in src]
    assert got == _rosbags_messages(bag, clock)
    assert got[0][1] == (101_000_000_005 if clock == "header" else 1_000_000_000)


def test_a_broken_message_names_file_number_topic_and_field(tmp_path):
    good = _odometry_bag(tmp_path / "good.bag", 3)
    with RosbagSource(good) as src:
        second = next(m for i, m in enumerate(src) if i == 1)
    raw = _raw_messages(good)[1]
    broken = raw[:12] + (4000).to_bytes(4, "little") + raw[16:]  # header.frame_id's length
    bag = _odometry_bag(tmp_path / "bad.bag", 3, broken={2: broken})
    with pytest.raises(SourceError, match=r"bad\.bag: cannot decode message 2 of the bag \(nav_msgs/msg/Odometry on "
                                          r"/odom, logged at 2000000000 ns\): field header\.frame_id: invalid string "
                                          r"length 4000 at offset 12"):  # fmt: skip
        with RosbagSource(bag) as src:
            list(src)
    assert json.loads(second.text)["header"]["seq"] == 2


def _raw_messages(path):
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        return [raw for _, _, raw in reader.messages()]


def test_types_without_a_formatter_and_refused_bytes_take_rosbags_path(tmp_path, shared_data, monkeypatch):
    from cclogfs.jsontext import roswire

    bag = _odometry_bag(tmp_path / "odom.bag", 5)
    expect = {p: _rosbags_messages(p) for p in (bag, shared_data("tf_example.bag"), shared_data("nav2_turtlebot.mcap"))}

    def refuses(raw):
        raise roswire.WireError("x", "refused")

    for make in (lambda self, t: None, lambda self, t: refuses):
        monkeypatch.setattr(roswire.WireFormatter, "get", make)
        for path, messages in expect.items():
            with RosbagSource(path) as src:
                assert [tuple(m) for m in src] == messages


def test_ros1chunks_reads_what_rosbags_reads(tmp_path, shared_data, monkeypatch):
    """Every connection selection, in rosbags' order; also through the general header parser."""
    from rosbags.highlevel import AnyReader

    from cclogfs.ingest import ros1chunks

    bags = [shared_data("tf_example.bag"), _odometry_bag(tmp_path / "odom.bag", 40),
            _odometry_bag(tmp_path / "chunks.bag", 40, chunk=4096)]  # fmt: skip
    for fixed in (ros1chunks._FIXED, 10**9):  # 10**9: no record fits the fast layouts
        monkeypatch.setattr(ros1chunks, "_FIXED", fixed)
        for bag in bags:
            with AnyReader([bag]) as reader:
                for conns in (reader.connections, reader.connections[::-1], reader.connections[-1:]):
                    want = [(c.id, t, raw) for c, t, raw in reader.messages(connections=conns)]
                    got = [(c.id, t, raw) for c, t, raw in ros1chunks.messages(reader.readers[0], conns, str(bag))]
                    assert got == want and want


def test_the_indexed_reader_reads_rosbags_index_and_fails_as_rosbags_fails(tmp_path, shared_data):
    """ros1chunks.IndexedReader: the same indexes (IndexData, in the same order) and
    connections as rosbags' reader; on a cut or altered index, rosbags' own error."""
    from rosbags.rosbag1 import Reader

    from cclogfs.ingest.ros1chunks import IndexedReader

    def opened(cls, path):
        try:
            with cls(path) as reader:
                indexes = {k: [(type(e), *e) for e in v] for k, v in reader.indexes.items()}
                return indexes, reader.connections, sorted(reader.chunks)
        except Exception as err:  # noqa: BLE001 - the failure is what is compared
            return type(err), str(err)

    bags = [shared_data("tf_example.bag"), _odometry_bag(tmp_path / "odom.bag", 40),
            _odometry_bag(tmp_path / "chunks.bag", 40, chunk=4096)]  # fmt: skip
    for bag in bags:
        want = opened(Reader, bag)
        assert opened(IndexedReader, bag) == want and isinstance(want[0], dict)
    # The second index data record (the first teaches rosbags the header's layout): its
    # count, its data size, both (a record that reads), a size past the end of the file.
    data = bags[2].read_bytes()
    op = data.index(b"op=\x04", data.index(b"op=\x04") + 1)
    count_at, size_at = data.index(b"count=", op - 50) + 6, data.rindex(b"/\0\0\0", 0, op) + 51
    count, size = struct.unpack_from("<I", data, count_at)[0], struct.unpack_from("<I", data, size_at)[0]
    for new_count, new_size in [(count + 1, size), (count, size + 12), (count + 1, size + 12), (10**6, 12 * 10**6)]:
        damaged = bytearray(data)
        struct.pack_into("<I", damaged, count_at, new_count)
        struct.pack_into("<I", damaged, size_at, new_size)
        bad = tmp_path / "bad.bag"
        bad.write_bytes(damaged)
        assert opened(IndexedReader, bad) == opened(Reader, bad)


def test_ros1chunks_refuses_a_record_that_is_not_the_indexed_message(tmp_path):
    bag = _odometry_bag(tmp_path / "odom.bag", 3)
    data = bag.read_bytes()
    at = data.index(b"op=\x02", data.index(b"op=\x02") + 1)  # the second message's record header
    bag.write_bytes(data[:at] + b"op=\x09" + data[at + 4 :])
    with pytest.raises(SourceError, match=r"odom\.bag: the chunk at byte [\d,]+ holds no whole message record"):
        with RosbagSource(bag) as src:
            list(src)
