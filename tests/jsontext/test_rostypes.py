"""cclogfs.jsontext.rostypes: each stream's message type (and, once, its ROS 1 definition)
in the metadata of the windows a recording stores."""

import pytest

from cclogfs.errors import InvalidInputError
from cclogfs.jsontext.rostypes import MAX_MSGDEF, StreamTypes, TypeCheck, ros1_description, ros1_typestore


def test_stream_types_keep_the_type_everywhere_and_the_definition_once():
    t = StreamTypes(lambda topic: {"msgdef": "x" * (MAX_MSGDEF + 1 if topic == "/big" else 10), "md5sum": "m"})
    t.saw("/a", "pkg/msg/A")
    t.saw("/big", "pkg/msg/B")
    assert t.meta("/a", {"kind": "all"}) == {"kind": "all", "msgtype": "pkg/msg/A", "msgdef": "x" * 10, "md5sum": "m"}
    assert t.meta("/a", {"kind": "all"}) == {"kind": "all", "msgtype": "pkg/msg/A"}
    assert t.meta("/big", {}) == {"msgtype": "pkg/msg/B", "md5sum": "m"}  # too big for a record's metadata
    assert t.meta("/untyped", {"k": 1}) == {"k": 1}


def test_the_first_type_seen_sticks_another_is_refused_and_an_empty_one_is_ignored():
    t = StreamTypes()
    t.saw("/a", "")
    assert t.meta("/a", {}) == {}
    t.saw("/a", "pkg/msg/A")
    t.saw("/a", "")
    # A stream keeps one type: another would leave windows export reads as the wrong type.
    with pytest.raises(InvalidInputError, match="on /a is a pkg/msg/Other, but the stream /a has type pkg/msg/A"):
        t.saw("/a", "pkg/msg/Other")
    assert t.meta("/a", {}) == {"msgtype": "pkg/msg/A"}  # no describe: the type only


def test_type_check_counts_the_messages_it_refuses_per_topic():
    c = TypeCheck()
    assert c.mismatch("/a", "pkg/msg/A") is None and c.mismatch("/b", "") is None
    assert "the stream /a has type pkg/msg/A" in c.mismatch("/a", "pkg/msg/B")
    c.mismatch("/a", "pkg/msg/B")
    assert c.mismatch("/a", "pkg/msg/A") is None
    assert c.refused == {"/a": 2}


def test_ros1_description_of_a_known_type():
    d = ros1_description(None, "nav_msgs/msg/Odometry")
    assert set(d) == {"msgdef", "md5sum"} and len(d["md5sum"]) == 32
    assert "geometry_msgs/PoseWithCovariance pose" in d["msgdef"]
    assert ros1_description(None, "std_msgs/msg/String", msgdef="string data", md5sum="abc",
                            latching=True) == {"msgdef": "string data", "md5sum": "abc", "latching": True}  # fmt: skip


def test_ros1_description_of_an_unknown_type_is_empty():
    assert ros1_description(None, "no_such_pkg/msg/Nothing") == {}


def test_ros1_typestore_adds_only_types_noetic_lacks():
    ts = ros1_typestore()
    assert "nav_msgs/msg/Odometry" in ts.fielddefs
