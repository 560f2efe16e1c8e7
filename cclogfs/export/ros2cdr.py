"""Stored JSON back to ROS 2 CDR, so an MCAP export reads as if `ros2 bag record` wrote it.

A stream is exported in CDR when its type (the window meta's `msgtype`) is one of the ROS 2
types rosbags ships (`Stores.LATEST`, the newest ROS 2 LTS it knows), or one whose
definition the window meta holds (`msgdef`). Its schema is what
rosbag2 writes: encoding `ros2msg`, named after the type, the definition with its
dependencies as rosbags generates it, and the channel carries the type's RIHS01 hash and
the QoS a player needs (`/tf_static` and ROS 1 latched topics transient-local, so late
subscribers still get them).

Each message is rebuilt from its JSON (`jsontext.rosmsg`) and serialized by rosbags. A key
the ROS 2 type lacks is refused, except: two that carry nothing a ROS 2 reader can use are
left out, a ROS 1 `header.seq` (a ROS 2 Header has no `seq`) and a definition constant with
its constant's value (older stores wrote them as fields, docs/JSON.md); and a key that is
a field the object lacks but for case is taken as it (ROS 1 `CameraInfo.D`, ROS 2 `d`).
A field the JSON lacks (one ROS 2 added, as `Range.variance`) is zero. Each of these is
counted per stream, field and message (`Ros2Types.notes`), for the caller to report.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Mapping
from io import StringIO
from typing import Any

from ..errors import InvalidInputError
from ..jsontext.rosmsg import Fit, build

HEADER = "std_msgs/msg/Header"
# Topics latched by convention, as ROS 2 recorders treat them (ingest/ros2qos.py).
LATCHED_BY_NAME = frozenset({"/tf_static"})

Encode = Callable[[str], bytes]
# stream -> what the store knows of its type ("msgtype", "msgdef", "latching"; play.pace.stream_types)
Describe = Callable[[str], Mapping[str, Any]]


def ros2_name(msgtype: str) -> str:
    """`pkg/msg/Type` for `pkg/Type` (the ROS 1 spelling a JSONL line may give)."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


class Ros2Types:
    """The ROS 2 types a CDR export can use, and what it had to leave out of messages."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.typestore = get_typestore(Stores.LATEST)
        self.notes: Counter[tuple[str, str]] = Counter()  # (stream, sentence with {n}) -> messages

    def why_not(self, msgtype: str, meta: Mapping[str, Any]) -> str | None:
        """None when `msgtype` can be written as CDR, else why not. A type rosbags does not
        ship is learnt from the ROS 1 definition `record` kept (`msgdef`, in the first
        window of a run; jsontext.rostypes): a lab's own message types."""
        if not msgtype:
            return "the store has no type for it"
        name = ros2_name(msgtype)
        if name in self.typestore.fielddefs:
            return None
        if not meta.get("msgdef"):
            return f"its type {msgtype} is not a ROS 2 type rosbags knows, and the window has no definition of it"
        from rosbags.typesys import get_types_from_msg

        try:
            types = get_types_from_msg(meta["msgdef"], name)
            # Types rosbags ships keep their ROS 2 definitions (a Header without seq).
            self.typestore.register({k: v for k, v in types.items() if k not in self.typestore.fielddefs})
            self.typestore.generate_msgdef(name, ros_version=2)
        except Exception as err:  # rosbags' parser raises several types for a bad definition
            return f"its stored definition of {msgtype} cannot be read: {err}"
        return None

    def schema(self, msgtype: str) -> tuple[str, str, bytes]:
        """(name, encoding, data) of the MCAP schema of `msgtype`, as rosbag2 writes it."""
        name = ros2_name(msgtype)
        text, _ = self.typestore.generate_msgdef(name, ros_version=2)
        return name, "ros2msg", text.encode()

    def channel_metadata(self, stream: str, msgtype: str, meta: Mapping[str, Any]) -> dict[str, str]:
        """The channel metadata rosbag2 writes: offered QoS (YAML) and the type hash."""
        return {"offered_qos_profiles": _qos_yaml(qos(stream, meta)),
                "topic_type_hash": self.typestore.hash_rihs01(ros2_name(msgtype))}  # fmt: skip

    def encoder(self, stream: str, msgtype: str) -> Encode:
        """JSON text -> CDR bytes of one stream's messages. Raises InvalidInputError naming
        the field at fault; the caller adds the stream and message."""
        name = ros2_name(msgtype)
        ts = self.typestore

        def encode(text: str) -> bytes:
            fit = _Ros2Fit(ts.fielddefs, stream, len(name) + 1)
            try:
                data = bytes(ts.serialize_cdr(build(ts, name, json.loads(text), fit=fit), name))
            except InvalidInputError:
                raise
            except Exception as err:  # rosbags' serializer; rosmsg has checked types and ranges
                raise InvalidInputError(f"{name}: {err}") from None
            self.notes.update(fit.notes)  # once per message, not per array element
            return data

        return encode


class _Ros2Fit(Fit):
    """A stored (maybe ROS 1) message into its ROS 2 type: what may be left out, renamed or
    zero-filled, each noted as a sentence with `{n}` for the number of messages."""

    def __init__(self, fielddefs: Mapping[str, Any], stream: str, skip: int) -> None:
        self.fielddefs, self.stream, self.skip = fielddefs, stream, skip
        self.notes: set[tuple[str, str]] = set()

    def extra(self, where: str, msgtype: str, key: str, value: Any, fields: list[str]) -> str | None:
        path = _field_path(where[self.skip :])
        if (msgtype == HEADER and key == "seq") or _is_constant(self.fielddefs, msgtype, key, value):
            self.notes.add((self.stream, f"{path} left out of {{n}} (not a field of the ROS 2 type)"))
            return ""
        same = [f for f in fields if f.lower() == key.lower()]  # ROS 1 CameraInfo.D is ROS 2's d
        if len(same) == 1:
            self.notes.add((self.stream, f"{path} written as ROS 2's {same[0]} in {{n}}"))
            return same[0]
        return None

    def missing(self, where: str, msgtype: str, field: str) -> None:
        path = _field_path(where[self.skip :])
        self.notes.add((self.stream, f"{path} missing from {{n}}, written as zero (a field of the ROS 2 type)"))


def _is_constant(fielddefs: Mapping[str, Any], owner: str, key: str, value: Any) -> bool:
    consts = fielddefs[owner][0]
    return any(cname == key and cvalue == value for cname, _, cvalue in consts)


def _field_path(where: str) -> str:
    """`transforms[3].header.seq` -> `transforms[].header.seq` (one count per field)."""
    out, depth = [], 0
    for ch in where:
        if ch == "[":
            depth += 1
            out.append("[]")
        elif ch == "]":
            depth -= 1
        elif depth == 0:
            out.append(ch)
    return "".join(out)


def stream_meta(ros2: Ros2Types, w: Any, describe: Describe | None) -> tuple[Mapping[str, Any], str | None]:
    """(meta, why not CDR) of a stream from its first selected window: when its type is one
    rosbags does not know, completed by `describe` with the definition a run's first window
    holds. Only then: `describe` may read every window of the stream."""
    msgtype = str(w.meta.get("msgtype") or "")
    why = ros2.why_not(msgtype, w.meta)
    if why is None or describe is None or not msgtype or "msgdef" in w.meta:
        return w.meta, why
    known = describe(w.name)
    if known.get("msgtype") != msgtype or "msgdef" not in known:
        return w.meta, why
    meta = {**known, **w.meta}
    return meta, ros2.why_not(msgtype, meta)


def qos(stream: str, meta: Mapping[str, Any]) -> Any:
    """The QoS a publisher of `stream` offered, as far as a store knows: reliable, and
    transient-local (depth 1) for a latched topic, volatile (depth 10) for the others."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    latched = stream in LATCHED_BY_NAME or bool(meta.get("latching"))
    never = QosTime(9223372036, 854775807)  # rmw's "infinite", as rosbag2 writes it
    return Qos(QosHistory.KEEP_LAST, 1 if latched else 10, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
               never, never, QosLiveliness.AUTOMATIC, never, False)  # fmt: skip


# What an MCAP export can do with such a stream; a rosbag2 bag is all CDR (`--encoding` is
# refused with --rosbag2, which the hint named too).
AS_JSON = "export it as JSON with --encoding json"
AS_JSON_MCAP = "export it to MCAP as JSON (--mcap OUT.mcap --encoding json)"


def message_error(stream: str, index: int, stamp_ns: int, window_seq: int | str, err: Exception, *,
                  as_json: str = AS_JSON) -> InvalidInputError:  # fmt: skip
    """The one-line error for a stored message the ROS 2 type cannot take."""
    return InvalidInputError(
        f"{stream}, message {index} (log time {stamp_ns} ns, window {window_seq}): {err}; "
        f"{as_json}, or leave the stream out with --topic."
    )


def _qos_yaml(profile: Any) -> str:
    """One offered QoS profile, YAML as rosbag2 (metadata version 9) writes it."""
    from rosbags.rosbag2.metadata import dump_qos_v9
    from ruamel.yaml import YAML

    out = StringIO()
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    yaml.dump(dump_qos_v9([profile]), out)
    return out.getvalue().strip()
