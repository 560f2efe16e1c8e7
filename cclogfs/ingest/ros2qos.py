"""Which QoS a ROS 2 recorder subscribes with, from what the publishers of a topic offer.

A subscription only gets messages from publishers whose QoS is compatible: a reliable
subscription gets nothing from best-effort publishers (sensor drivers), and a
transient-local one nothing from volatile publishers. Latched topics (/tf_static) need
transient-local, or a recorder started after the publisher misses them. So, as
`ros2 bag record` does: reliable unless some publisher is best-effort, transient-local
when every publisher is. Plain strings keep this testable without rclpy.
"""

from __future__ import annotations

from collections.abc import Iterable

LATCHED_BY_NAME = frozenset({"/tf_static"})  # before any publisher is seen


def choose_qos(topic: str, offered: Iterable[tuple[str, str]]) -> tuple[str, str]:
    """(reliability, durability) for a subscription to `topic`, given each publisher's
    (reliability, durability) as "reliable"/"best_effort" and "transient_local"/"volatile"."""
    offered = list(offered)
    if not offered:
        return ("reliable", "transient_local" if topic in LATCHED_BY_NAME else "volatile")
    reliability = "best_effort" if any(r == "best_effort" for r, _ in offered) else "reliable"
    durability = "transient_local" if all(d == "transient_local" for _, d in offered) else "volatile"
    return reliability, durability
