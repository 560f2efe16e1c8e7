"""The ROS 2 example's QoS choice: latched topics get transient-local, sensor topics best-effort."""

from cclogfs.ingest.ros2qos import choose_qos


def test_qos_follows_the_publishers():
    assert choose_qos("/tf_static", [("reliable", "transient_local")]) == ("reliable", "transient_local")
    assert choose_qos("/tf_static", []) == ("reliable", "transient_local")  # before its publisher appears
    assert choose_qos("/scan", [("best_effort", "volatile")]) == ("best_effort", "volatile")
    assert choose_qos("/odom", [("reliable", "volatile")]) == ("reliable", "volatile")
    assert choose_qos("/odom", []) == ("reliable", "volatile")
    # a best-effort publisher among reliable ones: best-effort gets them all
    assert choose_qos("/x", [("reliable", "volatile"), ("best_effort", "volatile")]) == ("best_effort", "volatile")
    # one volatile publisher: transient-local would not match it
    assert choose_qos("/x", [("reliable", "transient_local"), ("reliable", "volatile")]) == ("reliable", "volatile")
