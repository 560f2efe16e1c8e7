"""Publish stored messages on ROS 1 topics with their original types: `cclog play --to ros1://`.

Each stored JSON text is turned back into a rosbags message (`rosmsg`) and serialized
as ROS 1; rospy publishes the bytes under the stream's type name, MD5 and definition
(from the window metadata a recording wrote, else from rosbags' ROS 1 Noetic types), so
subscribers built for that type take them. No generated message classes are needed.
"""

from __future__ import annotations

import os
import time
from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from ..errors import InvalidInputError, SourceError
from ..ingest.ros1live import import_rospy, master_uri
from ..jsontext.rostypes import ros1_typestore
from ..jsontext.rosmsg import from_json

CLOCK_TYPE = "rosgraph_msgs/msg/Clock"


def ros1_name(msgtype: str) -> str:
    """nav_msgs/msg/Odometry -> nav_msgs/Odometry (ROS 1 has no /msg/ in type names)."""
    return msgtype.replace("/msg/", "/")


def raw_class(msgtype: str, md5sum: str, msgdef: str) -> type:
    """A rospy-publishable class whose instances carry already-serialized bytes."""
    import genpy

    class Raw(genpy.Message):
        __slots__ = ("_buff",)
        _type, _md5sum, _full_text, _has_header = ros1_name(msgtype), md5sum, msgdef, False

        def __init__(self, buff: bytes = b"") -> None:
            self._buff = buff

        def serialize(self, buff: Any) -> None:
            buff.write(self._buff)

    return Raw


class Ros1Publisher:
    """One rospy publisher per stream; `publish(stream, stamp_ns, text)` sends one message.

    `types`: stream -> metadata from `play.stream_types`; a stream without a known type
    is an error (it cannot be published as anything). `clock`: also publish /clock
    (rosgraph_msgs/Clock) with each message's stamp, for nodes with use_sim_time.
    """

    def __init__(self, uri: str, types: dict[str, dict[str, Any]], *, clock: bool = False,
                 node_name: str = "cclog_play", queue_size: int = 10000) -> None:  # fmt: skip
        self.rospy = rospy = import_rospy()
        import rosgraph

        master = master_uri(uri)
        if not rosgraph.is_master_online(master):
            raise SourceError(f"no ROS master answers at {master}: start roscore, or set ROS_MASTER_URI")
        self._streams: dict[str, tuple[Any, str, Any, Any]] = {}
        noetic = None
        for name, meta in types.items():
            msgtype = meta.get("msgtype")
            if not msgtype:
                raise InvalidInputError(f"stream {name} has no stored message type, so it cannot be published on ROS 1")
            if meta.get("msgdef") and meta.get("md5sum"):
                ts = get_typestore(Stores.EMPTY)
                ts.register(get_types_from_msg(meta["msgdef"], msgtype))
                msgdef, md5 = meta["msgdef"], meta["md5sum"]
            else:
                ts = noetic = noetic or ros1_typestore()
                if msgtype not in ts.fielddefs:
                    raise InvalidInputError(f"stream {name}: the type {msgtype} has no stored definition "
                                            "and is not a ROS 1 Noetic type")  # fmt: skip
                msgdef, md5 = ts.generate_msgdef(msgtype, ros_version=1)
            cls = raw_class(msgtype, md5, msgdef)
            self._streams[name] = (ts, msgtype, cls, None)
        os.environ["ROS_MASTER_URI"] = master
        rospy.init_node(node_name, anonymous=True, disable_signals=True, disable_rostime=True)
        for name, meta in types.items():
            ts, msgtype, cls, _ = self._streams[name]
            pub = rospy.Publisher(name, cls, queue_size=queue_size, latch=bool(meta.get("latching")))
            self._streams[name] = (ts, msgtype, cls, pub)
        self._clock = None
        if clock:
            ts = noetic or ros1_typestore()
            msgdef, md5 = ts.generate_msgdef(CLOCK_TYPE, ros_version=1)
            cls = raw_class(CLOCK_TYPE, md5, msgdef)
            self._clock = (ts, cls, rospy.Publisher("/clock", cls, queue_size=queue_size))
        self.published = 0

    def wait_for_subscribers(self, timeout: float | None = None) -> bool:
        """Block until every stream (and /clock) has a subscriber connected (False on timeout)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        pubs = [pub for *_, pub in self._streams.values()] + ([self._clock[2]] if self._clock else [])
        while any(pub.get_num_connections() == 0 for pub in pubs):
            if deadline is not None and time.monotonic() > deadline:
                return False
            time.sleep(0.05)
        return True

    def publish(self, name: str, stamp_ns: int, text: str) -> None:
        ts, msgtype, cls, pub = self._streams[name]
        if self._clock is not None:
            cts, ccls, cpub = self._clock
            stamp = cts.types["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
            cpub.publish(ccls(bytes(cts.serialize_ros1(cts.types[CLOCK_TYPE](clock=stamp), CLOCK_TYPE))))
        try:
            raw = ts.serialize_ros1(from_json(ts, msgtype, text), msgtype)
        except InvalidInputError as err:
            raise InvalidInputError(f"stream {name} at {stamp_ns}: cannot be published as {msgtype}: {err}") from None
        pub.publish(cls(bytes(raw)))
        self.published += 1

    def close(self, linger_s: float = 1.0) -> None:
        """Give the publishers' queues `linger_s` to drain, then shut the node down."""
        time.sleep(linger_s)
        for _, _, _, pub in self._streams.values():
            pub.unregister()
        self.rospy.signal_shutdown("cclog play: done")
