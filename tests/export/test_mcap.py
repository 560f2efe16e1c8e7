"""MCAP export (--encoding json) read back with the official mcap reader, byte for byte.
The ROS 2 CDR export is tested in test_mcap_ros2.py."""

from __future__ import annotations

import json

import pytest
from _windows import FakeWindow, fill_store, read_topics
from conftest import shared_data_file
from mcap.reader import make_reader

import cclogfs
from cclogfs.errors import InvalidInputError
from cclogfs.export import WINDOW_METADATA, export_mcap
from cclogfs.ingest import detect_format, open_source

TYPES = {"/odom": "nav_msgs/msg/Odometry", "/amcl_pose": "geometry_msgs/msg/PoseWithCovarianceStamped"}


def test_store_to_mcap_byte_exact(shared_data, tmp_path):
    data = read_topics(shared_data("nav2_turtlebot.mcap"), TYPES)
    store_path = fill_store(tmp_path / "store", data, msgtypes=TYPES)
    out = tmp_path / "out.mcap"
    with cclogfs.open_store(store_path, readonly=True) as store:
        windows = list(store.query())
        stats = export_mcap(store.query(), out, encoding="json")  # the stored text, as it is
        expect = {t: [] for t in TYPES}
        for w in windows:
            expect[w.name].extend(w.messages())
        metas = [(w.name, w.seq, w.start_ns, w.end_ns, w.meta) for w in windows]
    assert stats.windows == len(windows) and stats.messages == 2639 + 135
    assert expect == data  # the store kept the texts too

    got = {t: [] for t in TYPES}
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == set(TYPES)
        for topic, chan in channels.items():
            assert chan.message_encoding == "json"
            schema = summary.schemas[chan.schema_id]
            assert (schema.encoding, schema.name) == ("jsonschema", TYPES[topic])
            doc = json.loads(schema.data)
            pos = doc["properties"]["pose"]["properties"]["pose"]["properties"]["position"]
            assert pos["properties"]["x"] == {"type": "number"}
        for _, chan, msg in reader.iter_messages(log_time_order=False):
            got[chan.topic].append((msg.log_time, msg.data.decode("utf-8")))
            assert msg.publish_time == msg.log_time
        records = [m for m in reader.iter_metadata() if m.name == WINDOW_METADATA]
    assert got == expect  # every message, byte for byte, in order
    assert [
        (r.metadata["stream"], int(r.metadata["seq"]), int(r.metadata["start_ns"]),
         int(r.metadata["end_ns"]), json.loads(r.metadata["meta"]))
        for r in records
    ] == metas  # fmt: skip

    # Our own JSON-MCAP source reads the export back as well.
    assert detect_format(out) == "mcap-json"
    with open_source(out, ["/odom"]) as src:
        assert [(m.stamp_ns, m.text) for m in src] == data["/odom"]


def test_schema_named_by_stream_without_msgtype_and_empty_windows(tmp_path):
    windows = [
        FakeWindow("/a", 0, [(1, '{"x": 1, "tags": ["a"], "ok": true, "n": null}')]),
        FakeWindow("/b", 1, [(2, '{"y": {"z": 2.5}}'), (3, '{"y": {"z": -1}}')], {"k": 1}),
        FakeWindow("/a", 2, [(4, '{"x": 2}')]),
    ]
    out = tmp_path / "x.mcap"
    stats = export_mcap(windows, out, compression="none")
    assert (stats.windows, stats.messages, stats.streams) == (3, 4, {"/a", "/b"})
    with open(out, "rb") as f:
        reader = make_reader(f)
        msgs = [(c.topic, m.sequence, m.data) for _, c, m in reader.iter_messages()]
        summary = reader.get_summary()
    assert msgs == [
        ("/a", 0, b'{"x": 1, "tags": ["a"], "ok": true, "n": null}'),
        ("/b", 0, b'{"y": {"z": 2.5}}'),
        ("/b", 1, b'{"y": {"z": -1}}'),
        ("/a", 1, b'{"x": 2}'),
    ]
    schema = json.loads(next(s for s in summary.schemas.values() if s.name == "/a").data)
    assert schema["properties"] == {
        "x": {"type": "number"},
        "tags": {"type": "array", "items": {"type": "string"}},
        "ok": {"type": "boolean"},
        "n": {},
    }


def test_failed_export_leaves_no_file(tmp_path):
    def broken():
        yield FakeWindow("/a", 0, [(1, "{}")])
        raise cclogfs.CorruptionError("record 2 is damaged")

    out = tmp_path / "x.mcap"
    with pytest.raises(cclogfs.CorruptionError):
        export_mcap(broken(), out)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InvalidInputError, match="Unknown MCAP compression 'gzip'"):
        export_mcap([], out, compression="gzip")


@pytest.fixture(scope="module")
def twice(tmp_path_factory):
    """tf_example.bag recorded twice into one store (--append), in windows of 200 and then
    150 messages: every /tf window overlaps others in time, their edges apart."""
    from cclogfs.cli import main

    store = tmp_path_factory.mktemp("twice") / "s"
    bag = str(shared_data_file("tf_example.bag"))
    assert main(["record", bag, "--store", str(store)]) == 0
    assert main(["record", bag, "--store", str(store), "--append", "--chunk", "150"]) == 0
    with cclogfs.open_store(store, readonly=True) as s:
        stamps = sorted(t for w in s.query("/tf") for t, _ in w.messages())
    return str(store), stamps


@pytest.mark.parametrize("cut", [None, 0.3, 0.5, 0.71])
def test_sequence_increases_with_log_time_where_windows_overlap(twice, tmp_path, capsys, cut):
    """MCAP: a channel's sequence numbers "should be unique per channel and increasing over
    time". Written window after window, the two runs' /tf went back 512 times in log-time
    order. Cut with --start inside windows, the windows that start before it start later
    once cut, after windows the query gives after them: still merged in time order."""
    from cclogfs.cli import main

    store, stamps = twice
    rng = [] if cut is None else ["--start", f"{stamps[int(len(stamps) * cut)]}ns"]
    out = tmp_path / "out.mcap"
    assert main(["export", store, "--mcap", str(out), "--topic", "/tf", *rng]) == 0, capsys.readouterr().err
    with open(out, "rb") as f:
        read = [(m.log_time, m.sequence) for _, c, m in make_reader(f).iter_messages(log_time_order=False)]
    assert [t for t, _ in read] == sorted(t for t, _ in read)  # the file is in log-time order
    assert [s for _, s in read] == list(range(len(read)))  # so each channel counts up with it
    assert len(read) == len([s for s in stamps if cut is None or s >= stamps[int(len(stamps) * cut)]])
