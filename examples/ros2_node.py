#!/usr/bin/env python3
"""A ROS 2 node that hands every message of some topics to cclogfs.

    python3 examples/ros2_node.py /odom:nav_msgs/msg/Odometry /tf:tf2_msgs/msg/TFMessage

Needs a sourced ROS 2 install (rclpy) besides cclogfs. The subscriptions are `raw=True`:
rclpy passes the serialized bytes and never builds Python message objects, and cclogfs
decodes them with the same code that reads bags. Here the sink appends JSON Lines to
live.jsonl; a logging pipeline (classifier + store) is just another sink callable.
"""

from __future__ import annotations

import sys

from cclogfs.ingest.live import JsonlSink, LiveSource


def main(argv: list[str]) -> int:
    import rclpy  # imported here so that `--help` and tests work without ROS
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from rosidl_runtime_py.utilities import get_message

    specs = [arg.split(":", 1) for arg in argv] or [["/odom", "nav_msgs/msg/Odometry"]]
    sink = JsonlSink("live.jsonl")
    live = LiveSource(sink)
    rclpy.init()
    node = Node("cclogfs_logger")
    for topic, msgtype in specs:
        # Default arguments bind this topic's values into the callback.
        def callback(data: bytes, topic: str = topic, msgtype: str = msgtype) -> None:
            now = node.get_clock().now().nanoseconds  # used when the message has no header
            live.feed_cdr(topic, msgtype, data, recv_ns=now)

        node.create_subscription(
            get_message(msgtype), topic, callback, qos_profile_sensor_data, raw=True
        )
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.get_logger().info(f"logged {live.count} messages to live.jsonl")
        node.destroy_node()
        rclpy.try_shutdown()
        sink.close()
    return 0


if __name__ == "__main__":
    if {"-h", "--help"} & set(sys.argv[1:]):
        print(__doc__)
        sys.exit(0)
    sys.exit(main(sys.argv[1:]))
