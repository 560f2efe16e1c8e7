"""A topic whose message type changes within one input: a stream keeps one type (export and
play read all its windows as it), so the message of another type is a bad message, named by
file, line or message number, topic and both types; what came before it is stored."""

from __future__ import annotations

import json
import subprocess
import sys

from mcap.writer import Writer

from cclogfs import open_store

CCLOG = [sys.executable, "-m", "cclogfs"]


def line(stamp, msg, msgtype):
    return json.dumps({"topic": "/t", "stamp_ns": stamp, "msg": msg, "msgtype": msgtype}) + "\n"


def mixed_jsonl(path):
    path.write_text(line(1, {"data": "hi"}, "std_msgs/msg/String") + line(2, {"data": 5}, "std_msgs/msg/Int32")
                    + line(3, {"data": "ho"}, "std_msgs/msg/String"))  # fmt: skip


def stored(store_path, topic="/t"):
    with open_store(store_path, readonly=True) as store:
        return [(w.meta.get("msgtype"), [text for _, text in w.messages()]) for w in store.query(topic)]


def record(*args):
    return subprocess.run([*CCLOG, "record", *map(str, args)], capture_output=True, text=True)


def test_a_type_change_in_jsonl_stops_naming_the_line_and_keeps_what_came_before(tmp_path):
    src = tmp_path / "mixed.jsonl"
    mixed_jsonl(src)
    r = record(src, "--store", tmp_path / "s")
    assert r.returncode == 1, r.stderr
    assert (f"{src}, line 2: the message on /t is a std_msgs/msg/Int32, but the stream /t has type "
            "std_msgs/msg/String") in r.stderr  # fmt: skip
    assert "Traceback" not in r.stderr
    assert stored(tmp_path / "s") == [("std_msgs/msg/String", ['{"data": "hi"}'])]


def test_a_type_change_in_jsonl_is_skipped_and_counted_with_on_error_skip(tmp_path):
    src = tmp_path / "mixed.jsonl"
    mixed_jsonl(src)
    r = record(src, "--store", tmp_path / "s", "--on-error", "skip")
    assert r.returncode == 4, r.stderr
    assert f"cclog: skipped: {src}, line 2: the message on /t is a std_msgs/msg/Int32" in r.stderr
    assert f"{src}: SKIPPED 1 bad messages (named above), not stored" in r.stderr
    assert stored(tmp_path / "s") == [("std_msgs/msg/String", ['{"data": "hi"}', '{"data": "ho"}'])]
    r = subprocess.run([*CCLOG, "export", tmp_path / "s", "--mcap", tmp_path / "o.mcap"], capture_output=True,
                       text=True)  # fmt: skip
    assert r.returncode == 0, r.stderr


def test_a_second_channel_of_another_type_in_a_json_mcap_is_named(tmp_path):
    path = tmp_path / "mixed.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        a = w.register_channel("/t", "json", w.register_schema("demo/A", "jsonschema", b"{}"))
        b = w.register_channel("/t", "json", w.register_schema("demo/B", "jsonschema", b"{}"))
        for t, chan in ((1, a), (2, a), (3, b)):
            w.add_message(chan, log_time=t, data=b'{"x": 1}', publish_time=t)
        w.finish()
    r = record(path, "--store", tmp_path / "skip", "--on-error", "skip")
    assert r.returncode == 4 and f"{path}: SKIPPED 1 bad messages (named above)" in r.stderr, r.stderr
    assert stored(tmp_path / "skip") == [("demo/A", ['{"x": 1}', '{"x": 1}'])]
    r = record(path, "--store", tmp_path / "s")
    assert r.returncode == 1, r.stderr
    assert (f"{path}, message 3 (logged at 3 ns): the message on /t is a demo/B, but the stream /t has type "
            "demo/A") in r.stderr  # fmt: skip
    assert stored(tmp_path / "s") == [("demo/A", ['{"x": 1}', '{"x": 1}'])]


def test_a_second_connection_of_another_type_in_a_ros1_bag_is_named(tmp_path):
    from rosbags.rosbag1 import Writer as BagWriter
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    String, Int32 = ts.types["std_msgs/msg/String"], ts.types["std_msgs/msg/Int32"]
    path = tmp_path / "mixed.bag"
    with BagWriter(path) as bag:
        s = bag.add_connection("/t", "std_msgs/msg/String", typestore=ts)
        i = bag.add_connection("/t", "std_msgs/msg/Int32", typestore=ts)
        bag.write(s, 1, bytes(ts.serialize_ros1(String(data="hi"), "std_msgs/msg/String")))
        bag.write(i, 2, bytes(ts.serialize_ros1(Int32(data=5), "std_msgs/msg/Int32")))
        bag.write(s, 3, bytes(ts.serialize_ros1(String(data="ho"), "std_msgs/msg/String")))
    r = record(path, "--store", tmp_path / "skip", "--on-error", "skip")
    assert r.returncode == 4 and f"cclog: skipped: {path}, message 2 of the bag" in r.stderr, r.stderr
    assert f"{path}: SKIPPED 1 bad messages (named above)" in r.stderr
    assert "bad lines" not in r.stderr, r.stderr  # a bag has no lines
    assert stored(tmp_path / "skip") == [("std_msgs/msg/String", ['{"data": "hi"}', '{"data": "ho"}'])]
    r = record(path, "--store", tmp_path / "s")
    assert r.returncode == 1, r.stderr
    assert (f"{path}, message 2 of the bag (logged at 2 ns): the message on /t is a std_msgs/msg/Int32, but the "
            "stream /t has type std_msgs/msg/String") in r.stderr  # fmt: skip
    assert stored(tmp_path / "s") == [("std_msgs/msg/String", ['{"data": "hi"}'])]


def test_a_type_other_than_the_stores_is_refused_across_runs(tmp_path):
    """The check was per input: a later run (--append, or another file) stored /t as Int32
    into a store whose /t was String, and export then read all of /t as one type."""
    first, second = tmp_path / "first.jsonl", tmp_path / "second.jsonl"
    first.write_text(line(1, {"data": "hi"}, "std_msgs/msg/String"))
    second.write_text(line(2, {"data": "ho"}, "std_msgs/msg/String") + line(3, {"data": 5}, "std_msgs/msg/Int32")
                      + line(4, {"data": "hu"}, "std_msgs/msg/String"))  # fmt: skip
    assert record(first, "--store", tmp_path / "s").returncode == 0
    second_only = tmp_path / "second_only.jsonl"
    second_only.write_text(line(3, {"data": 5}, "std_msgs/msg/Int32"))
    for extra in ((), ("--append",)):
        r = record(second_only, "--store", tmp_path / "s", *extra)
        assert r.returncode == 1, r.stderr
        assert (f"cclog: error: {second_only}, line 1: the message on /t is a std_msgs/msg/Int32, but the stream /t "
                "has type std_msgs/msg/String in the store (recorded by an earlier run)") in r.stderr  # fmt: skip
        assert "Traceback" not in r.stderr
    r = record(second, "--store", tmp_path / "s", "--on-error", "skip")
    assert r.returncode == 4, r.stderr
    assert f"cclog: skipped: {second}, line 2: the message on /t is a std_msgs/msg/Int32" in r.stderr
    texts = [t for _, ts in stored(tmp_path / "s") for t in ts]
    assert texts == ['{"data": "hi"}', '{"data": "ho"}', '{"data": "hu"}']
    assert {t for t, _ in stored(tmp_path / "s")} == {"std_msgs/msg/String"}


def test_a_bag_of_another_type_than_the_stores_stream_is_named(tmp_path):
    from rosbags.rosbag1 import Writer as BagWriter
    from rosbags.typesys import Stores, get_typestore

    src = tmp_path / "first.jsonl"
    src.write_text(line(1, {"data": "hi"}, "std_msgs/msg/String"))
    assert record(src, "--store", tmp_path / "s").returncode == 0
    ts = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "int.bag"
    with BagWriter(path) as bag:
        i = bag.add_connection("/t", "std_msgs/msg/Int32", typestore=ts)
        bag.write(i, 2, bytes(ts.serialize_ros1(ts.types["std_msgs/msg/Int32"](data=5), "std_msgs/msg/Int32")))
    r = record(path, "--store", tmp_path / "s")
    assert r.returncode == 1, r.stderr
    assert (f"{path}, message 1 of the bag (logged at 2 ns): the message on /t is a std_msgs/msg/Int32, but the "
            "stream /t has type std_msgs/msg/String in the store") in r.stderr  # fmt: skip
    assert stored(tmp_path / "s") == [("std_msgs/msg/String", ['{"data": "hi"}'])]


def test_an_untyped_run_keeps_the_stores_type_so_a_later_run_cannot_change_it(tmp_path):
    """The store's type was read from a stream's newest window: a run of untyped lines
    (JSONL without msgtype) stored a newest window naming no type, and the next run then
    stored another type into the stream with exit 0 (found by attack: an Odometry /odom
    took a Twist, and export then failed on it)."""
    typed, untyped, other = tmp_path / "typed.jsonl", tmp_path / "untyped.jsonl", tmp_path / "other.jsonl"
    typed.write_text(line(1, {"data": "hi"}, "std_msgs/msg/String"))
    untyped.write_text(json.dumps({"topic": "/t", "stamp_ns": 2, "msg": {"data": "ho"}}) + "\n")
    other.write_text(line(3, {"data": 5}, "std_msgs/msg/Int32"))
    assert record(typed, "--store", tmp_path / "s").returncode == 0
    assert record(untyped, "--store", tmp_path / "s").returncode == 0
    r = record(other, "--store", tmp_path / "s")
    assert r.returncode == 1, r.stderr
    assert (f"cclog: error: {other}, line 1: the message on /t is a std_msgs/msg/Int32, but the stream /t "
            "has type std_msgs/msg/String in the store") in r.stderr  # fmt: skip
    # The untyped line joined its stream's type, as it does after a typed line of one input.
    assert stored(tmp_path / "s") == [("std_msgs/msg/String", ['{"data": "hi"}']),
                                      ("std_msgs/msg/String", ['{"data": "ho"}'])]  # fmt: skip
