#!/usr/bin/env python3
"""A ROS 2 node that hands every message of some topics to cclogfs.

    python3 examples/ros2_node.py robot.store [odom.model] /odom:nav_msgs/msg/Odometry /tf:tf2_msgs/msg/TFMessage

Needs a sourced ROS 2 install (rclpy) besides cclogfs. The subscriptions are `raw=True`:
rclpy passes the serialized bytes and never builds Python message objects, and cclogfs
decodes them with the same code that reads bags. Each message goes to a
`cclogfs.pipeline.Logger`: with a model (from `cclog train`), only the logging windows
around anomalies reach the store; without one, everything does. Ctrl-C flushes and syncs.
"""

from __future__ import annotations

import sys

from cclogfs.ingest.live import LiveSource
from cclogfs.pipeline import Logger


def main(argv: list[str]) -> int:
    import rclpy  # imported here so that `--help` and tests work without ROS
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
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

        node.create_subscription(
            get_message(msgtype), topic, callback, qos_profile_sensor_data, raw=True
        )
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
