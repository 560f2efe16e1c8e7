"""`cclog record ros1://` against a real ROS 1 master: roscore on a free port, `rosbag play`
of a real bag, the recording compared with the bag message by message.

Skips without ROS 1 (roscore, rosbag, rospy); under CI=true it fails instead, since
.ci/run installs ROS 1 from Debian's packages.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter

import pytest

from cclogfs import open_store
from cclogfs.errors import InvalidInputError
from cclogfs.ingest import open_source
from cclogfs.ingest.ros1live import TopicMatcher
from cclogfs.ingest.ros1testing import master as master_proxy
from cclogfs.ingest.ros1testing import (play, published, roscore, ros1_missing, start, stop, subscribers, wait_for,
                                        write_ros1_bag)  # fmt: skip
from cclogfs.runs import list_runs

CCLOG = [sys.executable, "-m", "cclogfs"]


@pytest.fixture(scope="module")
def ros1():
    why = ros1_missing()
    if why is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(f"ROS 1 is needed under CI (.ci/run installs it): {why}")
        pytest.skip(why)


@pytest.fixture(scope="module")
def master(ros1, tmp_path_factory):
    with roscore(tmp_path_factory.mktemp("ros")) as env:
        yield env


def by_topic(pairs):
    """topic -> Counter of JSON texts (the order of two topics' messages may differ live)."""
    out: dict[str, Counter] = {}
    for topic, text in pairs:
        out.setdefault(topic, Counter())[text] += 1
    return out


def bag_messages(bag, topics=None):
    with open_source(bag, topics=topics) as src:
        return by_topic((m.topic, m.text) for m in src)


def store_messages(path, skip=("/cclog/summary", "/cclog/runs")):
    with open_store(path, readonly=True) as store:
        return by_topic((w.name, t) for w in store.query() if w.name not in skip for _, t in w.messages())


def recorder(env, store, *args):
    """`cclog record ros1://` in the background; its stderr is read by `finish`."""
    return start([*CCLOG, "record", "ros1://", "--store", str(store), *args], env,
                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip


def finish(proc, after_s=1.0, sig=signal.SIGINT, rc=0):
    """Signal the recorder once what was played has had `after_s` to arrive; its stderr."""
    time.sleep(after_s)
    got = stop(proc, sig)
    err = proc.stderr.read()
    assert got == rc, err
    return err


def played(proc, timeout=120):
    _, err = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, err


def recorder_nodes(env):
    """The recorders' nodes the master knows, from the services each rospy node offers."""
    _, _, services = master_proxy(env).getSystemState("/cclog_test")[2]
    return {name.rsplit("/", 1)[0] for name, _ in services if name.startswith("/cclog_record")}


def wait_subscribed(env, topic, timeout=30):
    wait_for(lambda: any("cclog_record" in n for n in subscribers(env, topic)), timeout, f"a subscriber on {topic}")


def test_keep_all_records_every_message_of_a_real_bag(master, shared_data, tmp_path):
    bag = shared_data("tf_example.bag")
    rec = recorder(master, tmp_path / "live.store")  # every topic, found on the master as they appear
    try:
        played(play(master, bag, "--wait-for-subscribers", "--rate", "10"))
        err = finish(rec)
    finally:
        stop(rec)
    assert "stopped by SIGINT" in err and "/tf 517" in err and "/tf_static 1" in err
    got = store_messages(tmp_path / "live.store")
    want = bag_messages(bag)
    assert got["/tf"] == want["/tf"] and got["/tf_static"] == want["/tf_static"]
    assert sum(want["/tf"].values()) == 517
    with open_store(tmp_path / "live.store", readonly=True) as store:
        metas = [w.meta for w in store.query("/tf")]
    assert {m["msgtype"] for m in metas} == {"tf2_msgs/msg/TFMessage"}
    assert metas[0]["md5sum"] == "94810edda583a504dfda3829e70d7eec"  # the type's ROS 1 definition, once
    assert "msgdef" not in metas[1]


def test_latched_topic_is_received_after_it_was_published(master, shared_data, tmp_path):
    bag = write_ros1_bag(shared_data("tf_example.bag"), tmp_path / "latched.bag", latched=["/tf_static"])
    publisher = play(master, bag, "--keep-alive", "--topics", "/tf_static")
    try:
        # The one message is published before the recorder exists: only latching delivers it.
        wait_for(lambda: "/tf_static" in published(master), 30, "/tf_static to be published")
        time.sleep(0.5)
        rec = recorder(master, tmp_path / "s", "--topic", "/tf_static")
        try:
            wait_subscribed(master, "/tf_static")
            err = finish(rec, after_s=3.0)  # the latched message comes once the connection is made
        finally:
            stop(rec)
    finally:
        stop(publisher)
    assert store_messages(tmp_path / "s") == {"/tf_static": bag_messages(bag)["/tf_static"]}, err
    with open_store(tmp_path / "s", readonly=True) as store:
        assert next(iter(store.query("/tf_static"))).meta["latching"] is True


@pytest.fixture(scope="module")
def sim_bag_and_model(tmp_path_factory):
    """A simulated run with anomalies as a ROS 1 bag (/odom), and a model trained on a
    nominal run of the same robot."""
    d = tmp_path_factory.mktemp("sim")
    common = ["--rate", "30", "--robot-seed", "1"]
    subprocess.run([*CCLOG, "simulate", "--seed", "1", "--duration", "60", "--anomalies", "3", *common,
                    "--out", str(d / "run")], check=True, capture_output=True)  # fmt: skip
    subprocess.run([*CCLOG, "simulate", "--seed", "2", "--duration", "120", "--nominal", *common,
                    "--out", str(d / "nominal")], check=True, capture_output=True)  # fmt: skip
    subprocess.run([*CCLOG, "train", str(d / "nominal" / "run"), "--out", str(d / "model")], check=True,
                   capture_output=True)  # fmt: skip
    return write_ros1_bag(d / "run" / "run", d / "run.bag"), d / "model"


def windows_of(path, topic):
    with open_store(path, readonly=True) as store:
        return [(w.start_ns, w.end_ns, w.count, list(w.messages())) for w in store.query(topic)]


def test_smart_logging_live_keeps_the_windows_of_the_file(master, sim_bag_and_model, tmp_path):
    bag, model = sim_bag_and_model
    # Header stamps: the live receive times are the replay's, not the bag's log times.
    subprocess.run([*CCLOG, "record", str(bag), "--store", str(tmp_path / "file"), "--model", str(model),
                    "--clock", "header", "--window-max-s", "1000"], check=True, capture_output=True)  # fmt: skip
    rec = recorder(master, tmp_path / "live", "--model", str(model), "--topic", "/odom", "--clock", "header",
                   "--window-max-s", "1000")  # the same parts: no wall-clock cuts
    try:
        wait_subscribed(master, "/odom")
        played(play(master, bag, "--wait-for-subscribers", "--rate", "10"))
        assert "stopped by SIGTERM" in finish(rec, sig=signal.SIGTERM)  # SIGTERM flushes as Ctrl-C does
    finally:
        stop(rec)
    want = windows_of(tmp_path / "file", "/odom")
    assert want, "the simulated anomalies must open windows, or this test proves nothing"
    assert windows_of(tmp_path / "live", "/odom") == want
    assert bag_messages(bag)["/odom"].total() == 1800  # 60 s at 30 Hz, all played


def test_no_master_is_one_line_and_exit_1(ros1, tmp_path):
    from cclogfs.ingest.ros1testing import free_port

    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{free_port()}"}
    r = subprocess.run([*CCLOG, "record", "ros1://", "--store", str(tmp_path / "s")], env=env,
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert r.returncode == 1
    assert r.stderr.startswith("cclog: error: no ROS master answers at http://127.0.0.1:") and r.stderr.count("\n") == 1
    assert not (tmp_path / "s").exists()  # nothing created for a recording that could not start


def test_a_malformed_master_uri_is_one_line_and_exit_1(ros1, tmp_path):
    # rosgraph raised ValueError from deep inside is_master_online: a traceback, not a message
    cases = [("ros1://nonsense:xx", {}), ("ros1://", {"ROS_MASTER_URI": "garbage"}),
             ("ros1://", {"ROS_MASTER_URI": "http://localhost:abc"})]
    for uri, extra in cases:
        r = subprocess.run([*CCLOG, "record", uri, "--store", str(tmp_path / "s")], env={**os.environ, **extra},
                           capture_output=True, text=True, timeout=60)  # fmt: skip
        assert r.returncode == 1, (uri, extra, r.stderr)
        assert r.stderr.startswith("cclog: error: ") and r.stderr.count("\n") == 1, r.stderr
        assert "master URI" in r.stderr
        assert not (tmp_path / "s").exists()


def test_without_rospy_says_what_to_install(tmp_path):
    code = ("from cclogfs.ingest.ros1live import import_rospy\n"
            "import_rospy(paths=[])\n")  # fmt: skip
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if r.returncode == 0:
        pytest.skip("rospy is importable without the system paths here")
    assert "apt-get install ros-core python3-rospy" in r.stderr


def test_topic_matcher_names_patterns_and_exclusions():
    m = TopicMatcher(["/odom", "/tf.*"], exclude=["/tf_static"])
    assert [t for t in ["/odom", "/odom2", "/tf", "/tf_static", "/tfx", "/scan"] if m(t)] == ["/odom", "/tf", "/tfx"]
    assert TopicMatcher(None, exclude=["/rosout.*"])("/scan") and not TopicMatcher(None, ["/rosout.*"])("/rosout_agg")
    with pytest.raises(InvalidInputError, match="--exclude"):
        TopicMatcher(None, exclude=["("])


def test_play_to_ros1_publishes_every_message_with_its_type_and_clock(master, shared_data, tmp_path):
    bag = shared_data("tf_example.bag")
    subprocess.run([*CCLOG, "record", str(bag), "--store", str(tmp_path / "orig")], check=True, capture_output=True)
    rec = recorder(master, tmp_path / "back", "--topic", "/tf.*", "--topic", "/clock")  # names and patterns
    try:
        player = start([*CCLOG, "play", str(tmp_path / "orig"), "--to", "ros1://", "--rate", "10", "--clock",
                        "--wait-for-subscribers"], master, stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
        played(player)
        finish(rec)
    finally:
        stop(rec)
    back = store_messages(tmp_path / "back")
    clock = back.pop("/clock")
    assert back == store_messages(tmp_path / "orig") == bag_messages(bag)
    stamps = sorted(int(json.loads(t)["clock"]["sec"]) * 10**9 + json.loads(t)["clock"]["nanosec"] for t in clock)
    with open_store(tmp_path / "orig", readonly=True) as store:
        want = sorted(s for w in store.query() if w.name != "/cclog/runs" for s, _ in w.messages())
    assert stamps == want  # one /clock per message, at its stamp
    with open_store(tmp_path / "back", readonly=True) as store:
        assert {w.meta["msgtype"] for w in store.query("/tf")} == {"tf2_msgs/msg/TFMessage"}


# -- loss, told from header.seq ---------------------------------------------------------

def lost_lines(err):
    """The loss report of a recorder's stderr: the total line and the per-topic lines."""
    lines = err.splitlines()
    at = next(i for i, x in enumerate(lines) if "messages lost (from header.seq)" in x)
    return lines[at], [x.strip() for x in lines[at + 1:] if x.startswith("  ")]


def test_at_1x_nothing_is_lost_and_exit_0(master, sim_bag_and_model, tmp_path):
    bag, _ = sim_bag_and_model  # /odom, seq 1, 2, 3... as a ROS 1 publisher numbers it
    rec = recorder(master, tmp_path / "s", "--topic", "/odom")
    try:
        wait_subscribed(master, "/odom")
        played(play(master, bag, "--wait-for-subscribers", "--duration", "3"))  # 3 s at the bag's own 30 Hz
        err = finish(rec, after_s=0.5)  # exit 0 is asserted there
    finally:
        stop(rec)
    total, topics = lost_lines(err)
    n = store_messages(tmp_path / "s")["/odom"].total()
    assert 80 <= n <= 100, err  # about 3 s of 30 Hz
    assert total.endswith(": 0 messages lost (from header.seq)") and topics == [f"/odom: {n:,} received, 0 lost"]


SKIPPING_PUBLISHER = """
import sys, time
from cclogfs.ingest.ros1live import import_rospy
rospy = import_rospy()
from nav_msgs.msg import Odometry
from std_msgs.msg import String

class Numbered(Odometry):
    _has_header = False  # so rospy sends header.seq as set here instead of numbering it

rospy.init_node("skipper")
odom = rospy.Publisher("/odom", Numbered, queue_size=100)
text = rospy.Publisher("/text", String, queue_size=100)
while odom.get_num_connections() == 0 or text.get_num_connections() == 0:
    time.sleep(0.05)
time.sleep(0.5)
for seq in [int(s) for s in sys.argv[1].split(",")]:
    m = Numbered()
    m.header.seq = seq
    odom.publish(m)
    text.publish(String(data=str(seq)))
    time.sleep(0.01)
time.sleep(1.0)
"""


def test_a_seq_gap_is_reported_as_lost_with_exit_4(master, tmp_path):
    sent = [1, 2, 3, 4, 8, 9, 10, 11, 12, 15, 16]  # 5, 6, 7, 13 and 14 never arrive: 5 lost
    script = tmp_path / "skipper.py"
    script.write_text(SKIPPING_PUBLISHER)
    rec = recorder(master, tmp_path / "s", "--topic", "/odom", "--topic", "/text")
    try:
        wait_subscribed(master, "/odom")
        wait_subscribed(master, "/text")
        publisher = start([sys.executable, str(script), ",".join(map(str, sent))], master,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
        played(publisher, timeout=60)
        time.sleep(0.5)
        rc = stop(rec)
        err = rec.stderr.read()
    finally:
        stop(rec)
    assert rc == 4, err
    total, topics = lost_lines(err)
    assert "LOST 5 messages lost" in total
    assert topics == ["/odom: 11 received, 5 lost",
                      "/text: 11 received, not checked (std_msgs/String has no header.seq)"]
    assert store_messages(tmp_path / "s")["/odom"].total() == 11  # what did arrive is all stored
    assert "exit status" in subprocess.run([*CCLOG, "record", "--help"], capture_output=True, text=True).stdout


def test_seq_check_counts_gaps_per_publisher_and_says_what_it_cannot_tell():
    from cclogfs.ingest.ros1seq import SeqCheck, starts_with_header

    odom = {"type": "nav_msgs/Odometry", "md5sum": "a", "message_definition": "# c\n\nHeader header\nstring child"}
    tf = {"type": "tf2_msgs/TFMessage", "md5sum": "b", "message_definition": "geometry_msgs/TransformStamped[] t"}
    check = SeqCheck()
    for caller, seqs in [("/a", [7, 8, 10, 11]), ("/b", [1, 2, 3]), ("/a", [15])]:  # /a: 9, 12, 13, 14 lost
        for s in seqs:
            check.add("/odom", s.to_bytes(4, "little") + b"xx", {**odom, "callerid": caller})
    for s in [0, 0, 0]:  # a publisher that does not number: no gap can be told
        check.add("/scan", s.to_bytes(4, "little"), {**odom, "md5sum": "c", "callerid": "/z"})
    check.add("/tf", b"\0\0\0\0", tf)
    assert check.lost == 4
    assert check.lines() == ["  /odom: 8 received, 4 lost",
                             "  /scan: 3 received, not checked (seq does not go up one by one from /z)",
                             "  /tf: 1 received, not checked (tf2_msgs/TFMessage has no header.seq)"]  # fmt: skip
    check.not_stored = 2
    assert check.lost == 6
    assert check.lines()[-1] == "  2 received after the recording stopped taking messages, not stored"
    assert starts_with_header("std_msgs/Header header\n") and not starts_with_header("Header stamp_holder\n")


def test_stop_ends_the_recording_while_a_topic_keeps_publishing(master, tmp_path):
    talker = start(["rostopic", "pub", "-r", "100", "/chatter", "std_msgs/String", "data: hi"], master,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        rec = recorder(master, tmp_path / "s", "--topic", "/chatter")
        try:
            wait_subscribed(master, "/chatter")
            t0 = time.monotonic()
            err = finish(rec, after_s=1.0)  # exit 0: nothing known lost
            assert time.monotonic() - t0 < 6, err  # the stream never falls idle; stopping must not wait for it
        finally:
            stop(rec)
    finally:
        stop(talker)
    total, topics = lost_lines(err)
    n = store_messages(tmp_path / "s")["/chatter"].total()
    assert n > 0 and topics[0] == f"/chatter: {n:,} received, not checked (std_msgs/String has no header.seq)", err


def test_a_live_recording_is_a_run_and_is_never_refused(master, tmp_path):
    # A live master has no fixed content to compare: recording it again is a new run, not a copy.
    talker = start(["rostopic", "pub", "-r", "50", "/chatter", "std_msgs/String", "data: hi"], master,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        for _ in range(2):
            rec = recorder(master, tmp_path / "s", "--topic", "/chatter")
            try:
                wait_subscribed(master, "/chatter")
                finish(rec, after_s=1.0)
            finally:
                stop(rec)
    finally:
        stop(talker)
    with open_store(tmp_path / "s", readonly=True) as store:
        runs = list_runs(store)
        kept = store.streams()["/chatter"]["messages"]
    assert [(r.number, r.source, r.status) for r in runs] == [(1, "ros1://", "done"), (2, "ros1://", "done")]
    assert {r.start["master"] for r in runs} == {master["ROS_MASTER_URI"]}
    assert runs[0].options == {"topic": ["/chatter"]} and runs[0].end["signal"] == "SIGINT"
    assert runs[0].end["seq_lost"] == 0  # std_msgs/String has no header.seq: nothing known lost
    assert runs[0].kept > 0 and runs[0].kept + runs[1].kept == kept


def test_topics_that_match_nothing_or_deliver_nothing_are_said(master, tmp_path):
    # A --topic pattern no topic matches waited in silence, and a subscribed topic that
    # delivered nothing (a non-latched /tf_static published before the subscription) was
    # left out of the report: the user could not tell it had been missed.
    before = recorder_nodes(master)
    rec = recorder(master, tmp_path / "none.store", "--topic", "/nothing.*")
    # Its node is on the master: it is past its imports (2 s were not always enough on a loaded machine).
    wait_for(lambda: recorder_nodes(master) - before, 60, "the recorder's node")
    err = finish(rec, after_s=2.0, sig=signal.SIGTERM, rc=1)  # nothing recorded: an error (issue 12)
    assert "no topic on the master matches" in err.splitlines()[0], err
    rec = recorder(master, tmp_path / "quiet.store", "--topic", "/never_published")
    wait_subscribed(master, "/never_published")
    err = finish(rec, sig=signal.SIGTERM, rc=1)
    assert "received nothing on /never_published" in err, err


def test_a_headerless_topic_on_another_clock_than_the_stamps_is_said(master, tmp_path):
    # A bag played without its clock: /odom keeps its 2015 header stamps, /tf (no header)
    # gets the wall-clock receive time, years away. Smart logging's windows, on /odom's
    # clock, then never held /tf: 896 /tf messages received, none stored, not a word.
    subprocess.run([*CCLOG, "simulate", "--seed", "1", "--duration", "10", "--rate", "20", "--tf", "--nominal",
                    "--out", str(tmp_path / "run")], check=True, capture_output=True)  # fmt: skip
    bag = write_ros1_bag(tmp_path / "run" / "run", tmp_path / "run.bag")
    rec = recorder(master, tmp_path / "s", "--topic", "/odom", "--topic", "/tf", "--clock", "header")
    try:
        wait_subscribed(master, "/tf")
        played(play(master, bag, "--rate", "5"))
        err = finish(rec)
    finally:
        stop(rec)
    assert "/tf has no header stamp" in err and "/odom" in err and "another clock" in err, err


RETYPING_PUBLISHER = """
import time
from cclogfs.ingest.ros1live import import_rospy
rospy = import_rospy()
from std_msgs.msg import Int32, String

rospy.init_node("retyper")
for kind, values in ((String, ["a", "b", "c"]), (Int32, [1, 2, 3, 4])):  # the publisher restarts with another type
    pub = rospy.Publisher("/t", kind, queue_size=100)
    while pub.get_num_connections() == 0:
        time.sleep(0.05)
    time.sleep(0.5)
    for v in values:
        pub.publish(kind(data=v))
        time.sleep(0.01)
    time.sleep(0.5)
    pub.unregister()
"""


def test_a_publisher_restarting_with_another_type_is_skipped_said_and_exit_4(master, tmp_path):
    script = tmp_path / "retyper.py"
    script.write_text(RETYPING_PUBLISHER)
    rec = recorder(master, tmp_path / "s", "--topic", "/t")
    try:
        wait_subscribed(master, "/t")
        publisher = start([sys.executable, str(script)], master, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        played(publisher, timeout=60)
        time.sleep(0.5)
        rc = stop(rec)
        err = rec.stderr.read()
    finally:
        stop(rec)
    assert rc == 4, err  # the recording went on to the end, but a script must notice
    warning = ("the message on /t is a std_msgs/msg/Int32, but the stream /t has type std_msgs/msg/String")
    assert err.count(warning) == 1, err  # once per topic, not per message
    assert "ros1://: SKIPPED 4 messages whose type differs from their stream's, not stored: /t 4" in err
    assert sorted(store_messages(tmp_path / "s")["/t"]) == ['{"data": "a"}', '{"data": "b"}', '{"data": "c"}']
