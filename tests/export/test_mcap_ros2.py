"""Issue 12 item 4: an MCAP export carries ROS 2 CDR messages with `ros2msg` schemas for every
stream whose type rosbags knows, so rosbags (and `ros2 bag play`, Foxglove) read it as a bag
`ros2 bag record` wrote. Real bags are recorded with `cclog record`, exported with
`cclog export`, and every message read back with rosbags is compared with the stored JSON."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

import cclogfs
from cclogfs.runs import hidden_by_default
from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line
from cclogfs.jsontext.ros import MessageConverter


def record(bag, tmp_path, *extra):
    store = tmp_path / "s"
    assert main(["record", str(bag), "--store", str(store), *extra]) == 0
    return store


def stored(store):
    """{topic: [(stamp_ns, text)]} of every stored message, in window order (the runs'
    bookkeeping left out, as the export leaves it out)."""
    out: dict[str, list] = {}
    with cclogfs.open_store(store, readonly=True) as s:
        for w in s.query():
            if not hidden_by_default(w.name):
                out.setdefault(w.name, []).extend(w.messages())
    return out


def read_back(path):
    """{topic: [(log_time, JSON of the deserialized message)]}, as rosbags reads the file."""
    to_json = MessageConverter().to_json
    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        for con, log_time, raw in reader.messages():
            out.setdefault(con.topic, []).append((log_time, to_json(reader.deserialize(raw, con.msgtype))))
    return out


def without_seq(text):
    """The stored JSON of a ROS 1 message, less what a ROS 2 message cannot carry."""
    def strip(obj):
        if isinstance(obj, dict):
            if "stamp" in obj and "frame_id" in obj:  # a Header
                obj.pop("seq")
            for v in obj.values():
                strip(v)
        elif isinstance(obj, list):
            for v in obj:
                strip(v)
        return obj

    return json.dumps(strip(json.loads(text)))


def test_ros2_bag_export_reads_back_with_rosbags_field_for_field(shared_data, tmp_path, capsys):
    store = record(shared_data("nav2_turtlebot.mcap"), tmp_path)
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out)]) == 0
    err = capsys.readouterr().err
    assert "exported" in err and "note:" not in err  # every stream went as CDR, nothing left out
    want = stored(store)
    got = read_back(out)
    assert {t: len(m) for t, m in got.items()} == {"/odom": 2639, "/tf": 5422, "/tf_static": 1, "/amcl_pose": 135}
    # Every field of every message, and its log time: the text rosbags' message converts to
    # is the stored text, byte for byte (same fields, same values, same order).
    for topic, msgs in want.items():
        assert got[topic] == msgs, topic  # in order
    # publish_time is the stored log time too; sequence counts per channel.
    with open(out, "rb") as f:
        for _, chan, msg in make_reader(f).iter_messages(log_time_order=False):
            assert msg.publish_time == msg.log_time


def test_schemas_and_channels_are_what_rosbag2_writes(shared_data, tmp_path, capsys):
    bag = shared_data("nav2_turtlebot.mcap")
    store = record(bag, tmp_path)
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out)]) == 0
    with open(bag, "rb") as f:
        src = make_reader(f).get_summary()
    src_hash = {c.topic: c.metadata["topic_type_hash"] for c in src.channels.values()}
    ts = get_typestore(Stores.LATEST)
    with open(out, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    chans = {c.topic: c for c in summary.channels.values()}
    types = {"/odom": "nav_msgs/msg/Odometry", "/tf": "tf2_msgs/msg/TFMessage",
             "/tf_static": "tf2_msgs/msg/TFMessage", "/amcl_pose": "geometry_msgs/msg/PoseWithCovarianceStamped"}  # fmt: skip
    assert set(chans) == set(types)
    for topic, chan in chans.items():
        schema = summary.schemas[chan.schema_id]
        assert (chan.message_encoding, schema.encoding, schema.name) == ("cdr", "ros2msg", types[topic])
        assert schema.data.decode() == ts.generate_msgdef(types[topic], ros_version=2)[0]
        assert chan.metadata["topic_type_hash"] == src_hash[topic]  # the hash `ros2 bag record` wrote
    assert "durability: transient_local" in chans["/tf_static"].metadata["offered_qos_profiles"]
    assert "durability: volatile" in chans["/odom"].metadata["offered_qos_profiles"]


def test_ros1_bag_export_drops_header_seq_and_says_so(shared_data, tmp_path, capsys):
    store = record(shared_data("tf_example.bag"), tmp_path)
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out)]) == 0
    err = capsys.readouterr().err
    assert "note: /tf: transforms[].header.seq left out of 517 messages" in err
    assert "note: /tf_static: transforms[].header.seq left out of 1 message" in err
    want = {t: [(s, without_seq(x)) for s, x in msgs] for t, msgs in stored(store).items()}
    got = read_back(out)
    assert {t: len(m) for t, m in got.items()} == {"/tf": 517, "/tf_static": 1}
    for topic, msgs in want.items():
        assert got[topic] == msgs, topic  # in order
    # A latched ROS 1 topic stays latched for a ROS 2 player.
    with open(out, "rb") as f:
        chans = {c.topic: c for c in make_reader(f).get_summary().channels.values()}
    assert "transient_local" in chans["/tf_static"].metadata["offered_qos_profiles"]


def test_encoding_json_keeps_the_stored_text(shared_data, tmp_path, capsys):
    store = record(shared_data("nav2_turtlebot.mcap"), tmp_path, "--topic", "/amcl_pose")
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out), "--encoding", "json"]) == 0
    with open(out, "rb") as f:
        reader = make_reader(f)
        chan = next(iter(reader.get_summary().channels.values()))
        texts = [m.data.decode() for _, _, m in reader.iter_messages()]
        schema = reader.get_summary().schemas[chan.schema_id]
    assert (chan.message_encoding, schema.encoding, schema.name) == ("json", "jsonschema",
                                                                     "geometry_msgs/msg/PoseWithCovarianceStamped")
    assert texts == [t for _, t in stored(store)["/amcl_pose"]]


def jsonl_store(tmp_path, lines):
    tmp_path.mkdir(exist_ok=True)
    src = tmp_path / "in.jsonl"
    src.write_text("".join(lines))
    return record(src, tmp_path)


def test_unknown_type_goes_as_json_with_a_note(tmp_path, capsys):
    store = jsonl_store(tmp_path, [
        '{"topic": "/odd", "stamp_ns": 5, "msg": {"x": 1}, "msgtype": "acme_msgs/msg/Widget"}\n',
        '{"topic": "/plain", "stamp_ns": 6, "msg": {"y": 2}}\n',
        '{"topic": "/pose", "stamp_ns": 7, "msg": {"x": 1.5, "theta": 0.25}, "msgtype": "geometry_msgs/Pose2D"}\n',
    ])  # fmt: skip
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out)]) == 0
    err = capsys.readouterr().err
    assert "note: /odd exported as JSON, not CDR: its type acme_msgs/msg/Widget is not a ROS 2 type rosbags knows" in err
    assert "note: /plain exported as JSON, not CDR: the store has no type for it" in err
    assert "note: /pose: y missing from 1 message, written as zero (a field of the ROS 2 type)" in err
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        chans = {c.topic: (c.message_encoding, summary.schemas[c.schema_id].name) for c in summary.channels.values()}
        data = {c.topic: m.data for _, c, m in reader.iter_messages()}
    # A ROS 1 spelling (geometry_msgs/Pose2D) is the ROS 2 type geometry_msgs/msg/Pose2D; a
    # field the JSON lacks is zero, as in a message built in ROS 2.
    assert chans == {"/odd": ("json", "acme_msgs/msg/Widget"), "/plain": ("json", "/plain"),
                     "/pose": ("cdr", "geometry_msgs/msg/Pose2D")}  # fmt: skip
    assert data["/odd"] == b'{"x": 1}'
    ts = get_typestore(Stores.LATEST)
    pose = ts.deserialize_cdr(data["/pose"], "geometry_msgs/msg/Pose2D")
    assert (pose.x, pose.y, pose.theta) == (1.5, 0.0, 0.25)

    # --encoding cdr refuses what it cannot write as CDR, and leaves no file.
    assert main(["export", str(store), "--mcap", str(tmp_path / "cdr.mcap"), "--encoding", "cdr"]) == 1
    assert "/odd cannot be exported as CDR: its type acme_msgs/msg/Widget is not a ROS 2 type" in capsys.readouterr().err
    assert not (tmp_path / "cdr.mcap").exists()


@pytest.mark.parametrize("msg, field", [
    ('{"r": "far", "g": 0.0, "b": 0.0, "a": 1.0}', "std_msgs/msg/ColorRGBA.r: 'far' is not a float32"),
    ('{"r": 1.0, "colour": 3}', "std_msgs/msg/ColorRGBA has no field 'colour'"),
    ('{"r": [1.0]}', "std_msgs/msg/ColorRGBA.r: [1.0] is not a float32"),
    ('{"r": 1e50}', "std_msgs/msg/ColorRGBA.r: 1e+50 is out of range for a float32"),
    ('{"r": null}', "std_msgs/msg/ColorRGBA.r: null is not a value of std_msgs/msg/ColorRGBA.r"),
])  # fmt: skip
def test_a_value_the_type_cannot_take_is_refused_naming_stream_message_and_field(tmp_path, capsys, msg, field):
    typed = ', "msgtype": "std_msgs/msg/ColorRGBA"}\n'
    store = jsonl_store(tmp_path, [format_line("/pose", i, '{"r": 1.0}')[:-2] + typed for i in range(3)]
                        + [format_line("/pose", 3, msg)[:-2] + typed])  # fmt: skip
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out)]) == 1
    err = capsys.readouterr().err
    assert "/pose, message 3 (log time 3 ns, window" in err and field in err and "--encoding json" in err
    assert "Traceback" not in err and not out.exists() and list(tmp_path.glob("*.tmp")) == []
    # As JSON it goes.
    assert main(["export", str(store), "--mcap", str(out), "--encoding", "json"]) == 0


def test_integers_out_of_range_and_non_bools_are_refused_by_field(tmp_path, capsys):
    lines = [format_line("/n", 1, '{"data": 256}')[:-2] + ', "msgtype": "std_msgs/UInt8"}\n']
    store = jsonl_store(tmp_path, lines)
    assert main(["export", str(store), "--mcap", str(tmp_path / "o.mcap")]) == 1
    # The window's seq follows the run's start record (on /cclog/runs), so it is matched, not fixed.
    assert re.search(r"/n, message 0 \(log time 1 ns, window \d+\): std_msgs/msg/UInt8.data: 256 is out of range "
                     r"for a uint8 \(0 to 255\)", capsys.readouterr().err)  # fmt: skip
    store = jsonl_store(tmp_path / "b", [format_line("/b", 1, '{"data": "no"}')[:-2] + ', "msgtype": "std_msgs/Bool"}\n'])
    assert main(["export", str(store), "--mcap", str(tmp_path / "o.mcap")]) == 1
    assert "std_msgs/msg/Bool.data: 'no' is not a bool" in capsys.readouterr().err


def test_constants_older_stores_wrote_are_dropped_and_counted_a_wrong_one_refused(tmp_path, capsys):
    fix = ('{"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "gps"}, "status": {"STATUS_NO_FIX": -1, '
           '"STATUS_FIX": 0, "status": 0, "service": 1}, "latitude": 50.8, "longitude": 12.9, "altitude": 300.0, '
           '"position_covariance": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], "position_covariance_type": 0}')
    typed = ', "msgtype": "sensor_msgs/msg/NavSatFix"}\n'
    store = jsonl_store(tmp_path, [format_line("/fix", i, fix)[:-2] + typed for i in range(4)])
    assert main(["export", str(store), "--mcap", str(tmp_path / "o.mcap")]) == 0
    err = capsys.readouterr().err
    assert "note: /fix: status.STATUS_NO_FIX left out of 4 messages" in err
    assert "note: /fix: status.STATUS_FIX left out of 4 messages" in err
    back = read_back(tmp_path / "o.mcap")["/fix"]
    assert [json.loads(t)["status"] for _, t in back] == [{"status": 0, "service": 1}] * 4
    # A "constant" whose value is not the definition's is not a constant: refused.
    store = jsonl_store(tmp_path / "b", [format_line("/fix", 1, fix.replace('"STATUS_FIX": 0', '"STATUS_FIX": 7'))[:-2]
                                         + typed])  # fmt: skip
    assert main(["export", str(store), "--mcap", str(tmp_path / "b.mcap")]) == 1
    assert "sensor_msgs/msg/NavSatFix.status: sensor_msgs/msg/NavSatStatus has no field 'STATUS_FIX'" in \
        capsys.readouterr().err  # fmt: skip


def test_encoding_is_an_mcap_option(tmp_path, capsys, shared_data):
    store = jsonl_store(tmp_path, ['{"topic": "/a", "stamp_ns": 5, "msg": {"x": 1}}\n'])
    assert main(["export", str(store), "--parquet", str(tmp_path / "lake"), "--encoding", "cdr"]) == 1
    assert "--encoding is for --mcap" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["export", str(store), "--mcap", str(tmp_path / "o.mcap"), "--encoding", "ros1"])


def test_rosbag2_directory_opens_with_anyreader_field_for_field(shared_data, tmp_path, capsys):
    store = record(shared_data("tf_example.bag"), tmp_path)
    bag = tmp_path / "bag"
    assert main(["export", str(store), "--rosbag2", str(bag)]) == 0
    err = capsys.readouterr().err
    assert "windows, 518 messages of 2 streams" in err
    assert "note: /tf: transforms[].header.seq left out of 517 messages" in err
    assert sorted(p.name for p in bag.iterdir()) == ["bag.mcap", "metadata.yaml"]
    with AnyReader([bag]) as reader:  # a rosbag2 directory, read through its metadata.yaml
        assert {c.topic: (c.msgtype, c.msgcount) for c in reader.connections} == {
            "/tf": ("tf2_msgs/msg/TFMessage", 517), "/tf_static": ("tf2_msgs/msg/TFMessage", 1)}
        latched = {c.topic: c.ext.offered_qos_profiles[0].durability.name for c in reader.connections}
    assert latched == {"/tf": "VOLATILE", "/tf_static": "TRANSIENT_LOCAL"}
    want = {t: [(s, without_seq(x)) for s, x in msgs] for t, msgs in stored(store).items()}
    got = read_back(bag)
    for topic, msgs in want.items():
        assert got[topic] == msgs, topic  # in order

    # Replaced only with --force, and only a bag; a failed run leaves the old bag and no temporary.
    assert main(["export", str(store), "--rosbag2", str(bag)]) == 1
    assert "exists; pass --force" in capsys.readouterr().err
    (tmp_path / "notabag").mkdir()
    assert main(["export", str(store), "--rosbag2", str(tmp_path / "notabag"), "--force"]) == 1
    assert "is not a rosbag2 directory (no metadata.yaml)" in capsys.readouterr().err
    assert main(["export", str(store), "--rosbag2", str(bag), "--force", "--topic", "/tf_static"]) == 0
    with AnyReader([bag]) as reader:
        assert [c.topic for c in reader.connections] == ["/tf_static"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag", "notabag", "s"]


def test_rosbag2_refuses_a_stream_it_cannot_carry(tmp_path, capsys):
    store = jsonl_store(tmp_path, [
        format_line("/pose", 1, '{"x": 1.0}')[:-2] + ', "msgtype": "geometry_msgs/msg/Pose2D"}\n',
        '{"topic": "/odd", "stamp_ns": 5, "msg": {"x": 1}, "msgtype": "acme_msgs/msg/Widget"}\n',
    ])  # fmt: skip
    bag = tmp_path / "bag"
    assert main(["export", str(store), "--rosbag2", str(bag)]) == 1
    err = capsys.readouterr().err
    assert "/odd cannot go into a rosbag2 bag: its type acme_msgs/msg/Widget is not a ROS 2 type" in err
    assert not bag.exists() and not list(tmp_path.glob(".bag.*"))
    assert main(["export", str(store), "--rosbag2", str(bag), "--topic", "/pose"]) == 0
    assert main(["export", str(store), "--rosbag2", str(tmp_path / "b2"), "--encoding", "json"]) == 1


def test_ros1_field_names_and_fields_ros2_added_are_mapped_and_said(tmp_path, capsys):
    """A real ROS 1 bag (written by rosbags with Noetic's definitions) of CameraInfo, whose
    D/K/R/P are ROS 2's d/k/r/p, and Range, which ROS 2 extended with `variance`."""
    import numpy as np
    from rosbags.rosbag1 import Writer

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    bag = tmp_path / "cam.bag"
    with Writer(bag) as w:
        cam = w.add_connection("/camera_info", "sensor_msgs/msg/CameraInfo", typestore=ts)
        rng = w.add_connection("/range", "sensor_msgs/msg/Range", typestore=ts)
        for i in range(3):
            header = T["std_msgs/msg/Header"](seq=i, stamp=T["builtin_interfaces/msg/Time"](sec=10 + i, nanosec=5),
                                              frame_id="cam")  # fmt: skip
            info = T["sensor_msgs/msg/CameraInfo"](
                header=header, height=480, width=640, distortion_model="plumb_bob",
                D=np.array([0.1, -0.2, 0.0, 0.0, 0.01 * i]), K=np.arange(9, dtype=np.float64),
                R=np.eye(3).ravel(), P=np.arange(12, dtype=np.float64) / 7, binning_x=0, binning_y=0,
                roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))  # fmt: skip
            w.write(cam, (100 + i) * 10**9, ts.serialize_ros1(info, "sensor_msgs/msg/CameraInfo"))
            r = T["sensor_msgs/msg/Range"](header=header, radiation_type=1, field_of_view=0.5, min_range=0.1,
                                           max_range=4.0, range=1.25 + i)  # fmt: skip
            w.write(rng, (100 + i) * 10**9 + 1, ts.serialize_ros1(r, "sensor_msgs/msg/Range"))
    store = record(bag, tmp_path)
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out)]) == 0
    err = capsys.readouterr().err
    for line in ["note: /camera_info: D written as ROS 2's d in 3 messages", "note: /camera_info: P written as ROS 2's p",
                 "note: /camera_info: header.seq left out of 3 messages",
                 "note: /range: variance missing from 3 messages, written as zero"]:  # fmt: skip
        assert line in err
    got = read_back(out)
    want = stored(store)
    for (_, text), (_, back) in zip(want["/camera_info"], got["/camera_info"], strict=True):
        mine = json.loads(without_seq(text))
        assert json.loads(back) == {k.lower() if len(k) == 1 else k: v for k, v in mine.items()}
    for (_, text), (_, back) in zip(want["/range"], got["/range"], strict=True):
        assert json.loads(back) == {**json.loads(without_seq(text)), "variance": 0.0}


READING = """Header header
float32 temperature
uint16[] counts
string label
geometry_msgs/Point where
int8 MODE_A=1
uint8 mode
"""


def test_a_labs_own_ros1_type_goes_as_cdr_from_its_stored_definition(tmp_path, capsys):
    """A custom type rosbags does not ship: `record` keeps its ROS 1 definition, the export
    learns the type from it; rosbags reads the export with the ros2msg schema it carries."""
    import numpy as np
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import get_types_from_msg

    ts = get_typestore(Stores.ROS1_NOETIC)
    ts.register(get_types_from_msg(READING, "acme_msgs/msg/Reading"))
    msgdef, md5 = ts.generate_msgdef("acme_msgs/msg/Reading", ros_version=1)
    T = ts.types
    bag = tmp_path / "lab.bag"
    with Writer(bag) as w:
        conn = w.add_connection("/reading", "acme_msgs/msg/Reading", msgdef=msgdef, md5sum=md5)
        for i in range(450):
            header = T["std_msgs/msg/Header"](seq=i, stamp=T["builtin_interfaces/msg/Time"](sec=i, nanosec=7),
                                              frame_id="lab")  # fmt: skip
            msg = T["acme_msgs/msg/Reading"](
                header=header, temperature=np.float32(20 + i / 8), counts=np.arange(i % 5, dtype=np.uint16),
                label=f"r{i}", where=T["geometry_msgs/msg/Point"](x=i / 3, y=-1.0, z=0.5), mode=i % 3)  # fmt: skip
            w.write(conn, (1000 + i) * 10**9, ts.serialize_ros1(msg, "acme_msgs/msg/Reading"))
    store = record(bag, tmp_path)
    out = tmp_path / "out.mcap"
    assert main(["export", str(store), "--mcap", str(out)]) == 0
    err = capsys.readouterr().err
    assert "exported as JSON" not in err and "note: /reading: header.seq left out of 450 messages" in err
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    (chan,) = summary.channels.values()
    schema = summary.schemas[chan.schema_id]
    assert (chan.message_encoding, schema.name, schema.encoding) == ("cdr", "acme_msgs/msg/Reading", "ros2msg")
    assert "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n" in schema.data.decode()
    want = [(s, without_seq(x)) for s, x in stored(store)["/reading"]]
    assert read_back(out)["/reading"] == want  # every field of all 450 messages, in order

    # Windows later in the run than the one holding the definition: the export finds it.
    late = tmp_path / "late.mcap"
    assert main(["export", str(store), "--mcap", str(late), "--start", "1400"]) == 0
    assert "exported as JSON" not in capsys.readouterr().err
    with cclogfs.open_store(store, readonly=True) as s:
        windows = [w for w in s.query(start_ns=1400 * 10**9) if not hidden_by_default(w.name)]
        assert "msgdef" not in windows[0].meta, "the selection must not start at the defining window"
        late_want = [(t, without_seq(x)) for w in windows for t, x in w.messages() if t >= 1400 * 10**9]
    assert read_back(late)["/reading"] == late_want

    # Without any stored definition (a JSONL source naming the type): JSON, and said why.
    src = tmp_path / "r.jsonl"
    assert main(["convert", str(bag), "-o", str(src)]) == 0
    src.write_text("".join(line[:-2] + ', "msgtype": "acme_msgs/msg/Reading"}\n' for line in src.open()))
    assert main(["record", str(src), "--store", str(tmp_path / "j")]) == 0
    assert main(["export", str(tmp_path / "j"), "--mcap", str(tmp_path / "j.mcap")]) == 0
    assert "note: /reading exported as JSON, not CDR: its type acme_msgs/msg/Reading is not a ROS 2 type " \
           "rosbags knows, and the window has no definition of it" in capsys.readouterr().err  # fmt: skip


def test_rosbag2_export_removes_the_work_directory_a_killed_one_left(shared_data, tmp_path, capsys):
    """Found by attack: a killed export left its hidden work directory `.OUT.*.tmp` for good;
    the next removes one whose writer is dead, not one of a live export."""
    store = record(shared_data("tf_example.bag"), tmp_path)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        for pid in (dead.pid, live.pid):
            (tmp_path / f".bag.{pid}.ab_cd123.tmp" / "bag").mkdir(parents=True)
            (tmp_path / f".bag.{pid}.ab_cd123.tmp" / "bag" / "bag.mcap").write_bytes(b"half a bag")
        assert main(["export", str(store), "--rosbag2", str(tmp_path / "bag")]) == 0
        left = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".bag."))
        assert left == [f".bag.{live.pid}.ab_cd123.tmp"]
    finally:
        live.kill()
        live.wait()


def test_rosbag2_export_syncs_the_bag_before_the_rename(shared_data, tmp_path, capsys, renames_and_fsyncs):
    """Found by attack: the bag was renamed into place unsynced (a power cut could leave a
    partial bag under the final name)."""
    store = record(shared_data("tf_example.bag"), tmp_path)
    ops = renames_and_fsyncs
    assert main(["export", str(store), "--rosbag2", str(tmp_path / "bag")]) == 0
    at = ops.index(("replace", str(tmp_path / "bag")))
    synced = {os.path.basename(p) for op, p in ops[:at] if op == "fsync"}
    assert {"bag.mcap", "metadata.yaml", "bag"} <= synced, ops
    assert ("fsync", str(tmp_path)) in ops[at:], ops
