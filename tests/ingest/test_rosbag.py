"""cclogfs.ingest.rosbag: ROS 1 and ROS 2 bags (rosbags), messages as JSON text."""

from __future__ import annotations

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
