"""ROS messages for a simulated run: rosbags objects for the bag, and their JSON text.

The JSON of a few hundred thousand messages through `message_to_json` takes tens of
seconds, so the text is made from a template instead: `message_to_json` renders one
message whose variable fields hold sentinel values, and the sentinels become `%r`/`%d`
slots. The text is then the same by construction (field order, spelling, float repr),
and the tests compare it with `message_to_json` of the messages read back from the bag.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from rosbags.typesys import Stores, get_typestore

from ..jsontext.ros import message_to_json

__all__ = ["TYPESTORE", "Columns", "ODOM", "IMU", "TF", "TopicSpec"]

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)
_T = TYPESTORE.types
Time = _T["builtin_interfaces/msg/Time"]
Header = _T["std_msgs/msg/Header"]
Point = _T["geometry_msgs/msg/Point"]
Vector3 = _T["geometry_msgs/msg/Vector3"]
Quaternion = _T["geometry_msgs/msg/Quaternion"]

# diff_drive_controller's defaults: x, y and yaw known, z/roll/pitch meaningless
_ODOM_COV = np.diag([0.001, 0.001, 1e6, 1e6, 1e6, 1e3]).ravel()
_IMU_ORI_COV = np.diag([1e6, 1e6, 0.01]).ravel()
_IMU_GYRO_COV = np.diag([1e-4, 1e-4, 1e-4]).ravel()
_IMU_ACC_COV = np.diag([2.5e-3, 2.5e-3, 2.5e-3]).ravel()

# CDR types of the integer fields (builtin_interfaces/Time); every other field is float64.
_CDR_DTYPES = {"sec": "<i4", "nanosec": "<u4"}

Columns = dict[str, list]  # field name -> one Python value per message


def _odom(c: dict[str, Any]) -> Any:
    o = _T["nav_msgs/msg/Odometry"]
    return o(
        header=Header(stamp=Time(sec=c["sec"], nanosec=c["nanosec"]), frame_id="odom"),
        child_frame_id="base_link",
        pose=_T["geometry_msgs/msg/PoseWithCovariance"](
            pose=_T["geometry_msgs/msg/Pose"](
                position=Point(x=c["x"], y=c["y"], z=0.0),
                orientation=Quaternion(x=0.0, y=0.0, z=c["qz"], w=c["qw"]),
            ),
            covariance=_ODOM_COV,
        ),
        twist=_T["geometry_msgs/msg/TwistWithCovariance"](
            twist=_T["geometry_msgs/msg/Twist"](
                linear=Vector3(x=c["vx"], y=0.0, z=0.0),
                angular=Vector3(x=0.0, y=0.0, z=c["wz"]),
            ),
            covariance=_ODOM_COV,
        ),
    )


def _imu(c: dict[str, Any]) -> Any:
    return _T["sensor_msgs/msg/Imu"](
        header=Header(stamp=Time(sec=c["sec"], nanosec=c["nanosec"]), frame_id="imu_link"),
        orientation=Quaternion(x=0.0, y=0.0, z=c["qz"], w=c["qw"]),
        orientation_covariance=_IMU_ORI_COV,
        angular_velocity=Vector3(x=0.0, y=0.0, z=c["gz"]),
        angular_velocity_covariance=_IMU_GYRO_COV,
        linear_acceleration=Vector3(x=c["ax"], y=c["ay"], z=c["az"]),
        linear_acceleration_covariance=_IMU_ACC_COV,
    )


def _tf(c: dict[str, Any]) -> Any:
    ts = _T["geometry_msgs/msg/TransformStamped"](
        header=Header(stamp=Time(sec=c["sec"], nanosec=c["nanosec"]), frame_id="odom"),
        child_frame_id="base_link",
        transform=_T["geometry_msgs/msg/Transform"](
            translation=Vector3(x=c["x"], y=c["y"], z=0.0),
            rotation=Quaternion(x=0.0, y=0.0, z=c["qz"], w=c["qw"]),
        ),
    )
    return _T["tf2_msgs/msg/TFMessage"](transforms=[ts])


@dataclass(frozen=True)
class TopicSpec:
    """A topic the simulator can publish: its type, message builder and JSON template."""

    topic: str
    msgtype: str
    build: Callable[[dict[str, Any]], Any]
    int_fields: tuple[str, ...]
    float_fields: tuple[str, ...]

    def __post_init__(self) -> None:
        # Render sentinels through message_to_json and turn them into format slots.
        sentinels: dict[str, Any] = {}
        for k, name in enumerate(self.int_fields):
            sentinels[name] = 900_000_001 + k
        for k, name in enumerate(self.float_fields):
            sentinels[name] = float(f"{k + 2}.25e-301")
        text = message_to_json(self.build(sentinels)).replace("%", "%%")
        by_token = {str(v) if isinstance(v, int) else repr(v): n for n, v in sentinels.items()}
        order: list[str] = []

        def slot(m: re.Match) -> str:
            name = by_token[m.group(2)]
            order.append(name)
            return m.group(1) + ("%d" if name in self.int_fields else "%r")

        pattern = "|".join(re.escape(t) for t in by_token)
        template = re.sub(rf"(: )({pattern})(?=[,}}\]])", slot, text)
        if sorted(order) != sorted(sentinels):
            raise AssertionError(f"template for {self.msgtype} lost a field: {order}")
        object.__setattr__(self, "template", template)
        object.__setattr__(self, "order", tuple(order))
        # The same trick for CDR: every message has the same length (fixed strings), so
        # a serialized sentinel message is a byte template with a fixed offset per field.
        raw = bytes(TYPESTORE.serialize_cdr(self.build(sentinels), self.msgtype))
        offsets = {}
        for name, value in sentinels.items():
            needle = np.array([value], dtype=_CDR_DTYPES.get(name, "<f8")).tobytes()
            if raw.count(needle) != 1:
                raise AssertionError(f"CDR template for {self.msgtype}: field {name} not unique")
            offsets[name] = raw.index(needle)
        object.__setattr__(self, "cdr_template", np.frombuffer(raw, np.uint8))
        object.__setattr__(self, "cdr_offsets", offsets)

    def texts(self, cols: Columns) -> list[str]:
        """The JSON text of every message, from per-field value lists."""
        tpl, order = self.template, self.order  # type: ignore[attr-defined]
        return [tpl % vals for vals in zip(*(cols[n] for n in order))]

    def cdr(self, cols: dict[str, np.ndarray]) -> list[bytes]:
        """CDR bytes of every message (what serialize_cdr gives), from per-field arrays."""
        tpl = self.cdr_template  # type: ignore[attr-defined]
        n = len(next(iter(cols.values())))
        buf = np.tile(tpl, (n, 1))
        for name, off in self.cdr_offsets.items():  # type: ignore[attr-defined]
            col = np.ascontiguousarray(cols[name], dtype=_CDR_DTYPES.get(name, "<f8"))
            buf[:, off : off + col.itemsize] = col.view(np.uint8).reshape(n, col.itemsize)
        return [row.tobytes() for row in buf]

    def messages(self, cols: Columns) -> list[Any]:
        """rosbags message objects, one per row."""
        names = list(cols)
        return [self.build(dict(zip(names, row))) for row in zip(*cols.values())]


ODOM = TopicSpec("/odom", "nav_msgs/msg/Odometry", _odom, ("sec", "nanosec"),
                 ("x", "y", "qz", "qw", "vx", "wz"))
IMU = TopicSpec("/imu", "sensor_msgs/msg/Imu", _imu, ("sec", "nanosec"),
                ("qz", "qw", "gz", "ax", "ay", "az"))
TF = TopicSpec("/tf", "tf2_msgs/msg/TFMessage", _tf, ("sec", "nanosec"), ("x", "y", "qz", "qw"))
