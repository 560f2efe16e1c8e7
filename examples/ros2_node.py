#!/usr/bin/env python3
"""A ROS 2 node that hands every message of some topics to cclogfs.

    python3 examples/ros2_node.py robot.store [odom.model] /odom:nav_msgs/msg/Odometry /tf_static:tf2_msgs/msg/TFMessage

Needs a sourced ROS 2 install (rclpy) besides cclogfs. NOT RUN on this project's machines
(no ROS 2 there); the parts it shares with `cclog record` are: the CDR bytes go through
the same rosbags decoding and rosbridge JSON as bag files (`LiveSource.feed_cdr`, tested
against the bags in tests/test_ingest_live.py), the QoS choice (`choose_qos`, tested in
tests/test_live_ros2qos.py), and the pipeline (`Logger`).

Subscriptions are `raw=True`: rclpy passes the serialized bytes and never builds Python
message objects. Each topic's QoS follows its publishers (`choose_qos`): reliable unless
a publisher is best-effort, transient-local when every publisher is, so latched
/tf_static is received even when it was published before this node started. Each message
goes to a `cclogfs.pipeline.Logger`: with a model (from `cclog train`), only the logging
windows around anomalies reach the store; without one, everything does, and each stream's
message type is kept in its windows' metadata. Ctrl-C or SIGTERM flushes and syncs.
The QoS is chosen when the node starts, from the publishers present then: start it after
the drivers of best-effort (sensor) topics.
"""

from __future__ import annotations

import signal
import sys

from cclogfs.ingest.live import LiveSource
from cclogfs.ingest.ros2qos import choose_qos
from cclogfs.pipeline import Logger


def qos_for(node, topic: str):
    """The rclpy QoS profile `choose_qos` picks from the topic's publishers right now."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    offered = [
        ("best_effort" if i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT else "reliable",
         "transient_local" if i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL else "volatile")
        for i in node.get_publishers_info_by_topic(topic)
    ]  # fmt: skip
    reliability, durability = choose_qos(topic, offered)
    return QoSProfile(
        depth=1000,  # a burst waits here instead of being dropped
        reliability=ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort" else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if durability == "transient_local" else DurabilityPolicy.VOLATILE,
    )


def main(argv: list[str]) -> int:
    import rclpy  # imported here so that `--help` and tests work without ROS
    from rclpy.node import Node
    from rosidl_runtime_py.utilities import get_message

    store, rest = argv[0], argv[1:]
    model = rest.pop(0) if rest and ":" not in rest[0] else None
    specs = [arg.split(":", 1) for arg in rest] or [["/odom", "nav_msgs/msg/Odometry"]]
    sink = Logger(store, model=model)
    live = LiveSource(sink)
    rclpy.init()
    node = Node("cclogfs_logger")
    for topic, msgtype in specs:
        # Default arguments bind this topic's values into the callback.
        def callback(data: bytes, topic: str = topic, msgtype: str = msgtype) -> None:
            now = node.get_clock().now().nanoseconds  # used when the message has no header
            live.feed_cdr(topic, msgtype, data, recv_ns=now)

        node.create_subscription(get_message(msgtype), topic, callback, qos_for(node, topic), raw=True)

    def on_sigterm(signum, frame):
        raise KeyboardInterrupt  # the same clean end as Ctrl-C

    signal.signal(signal.SIGTERM, on_sigterm)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.get_logger().info(f"handed {live.count} messages to the logger of {store}")
        node.destroy_node()
        rclpy.try_shutdown()
        sink.close()
    return 0


if __name__ == "__main__":
    if not sys.argv[1:] or {"-h", "--help"} & set(sys.argv[1:]):
        print(__doc__)
        sys.exit(0)
    sys.exit(main(sys.argv[1:]))
