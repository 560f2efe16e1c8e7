"""Messages from a running ROS 2 program, turned into `SourceMessage`s for a sink.

A node hands each message to `LiveSource.feed` (an rclpy message object) or, cheaper,
subscribes with `raw=True` and hands the serialized bytes to `feed_cdr`: rclpy then
never builds the Python message, and the bytes are read by the same rosbags type
store and JSON conversion as bag files, so live and recorded logs give the same text.
The sink is any callable: the logging pipeline, a `JsonlSink`, a list's `append`.
See examples/ros2_node.py.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from ..errors import InvalidInputError, SourceError
from ..jsontext.ros import message_stamp_ns
from .base import SourceMessage, check_clock
from ..jsontext.ros import MessageConverter
from ..jsontext.lines import format_line

Sink = Callable[[SourceMessage], None]


class LiveSource:
    """Converts live messages to rosbridge JSON and passes each to `sink`, one at a time.

    Safe to call from several executor threads: conversion runs in parallel, sink calls
    are serialized. `stamp_ns` is `recv_ns` (else the clock at arrival): the log time, one
    clock for all topics; with clock="header" the header.stamp, else the log time.
    """

    def __init__(
        self,
        sink: Sink,
        *,
        distro: Stores = Stores.LATEST,
        clock_ns: Callable[[], int] = time.time_ns,
        clock: str = "log",
    ) -> None:
        self._sink = sink
        self._header_clock = check_clock(clock) == "header"
        self._clock_ns = clock_ns
        self._typestore = get_typestore(distro)
        self._converter = MessageConverter()
        self._lock = threading.Lock()
        self.count = 0

    def add_type(self, msgtype: str, definition: str) -> None:
        """Teach the type store a message type it does not ship (the .msg file's text)."""
        self._typestore.register(get_types_from_msg(definition, msgtype))

    def feed_cdr(
        self, topic: str, msgtype: str, data: bytes | memoryview, recv_ns: int | None = None
    ) -> SourceMessage:
        """Log one serialized (CDR) message, as an rclpy `raw=True` subscription gets it."""
        if msgtype not in self._typestore.fielddefs:
            raise SourceError(
                f"Message type {msgtype!r} on {topic} is unknown to the type store; "
                "register its definition with add_type()."
            )
        try:
            msg = self._typestore.deserialize_cdr(data, msgtype)
        except Exception as err:
            raise SourceError(f"Cannot decode the {msgtype} message on {topic}: {err}") from err
        return self._emit(topic, msgtype, msg, recv_ns)

    def feed(self, topic: str, msg: Any, recv_ns: int | None = None) -> SourceMessage:
        """Log one message object: an rclpy message, or a rosbags one."""
        msgtype = getattr(msg, "__msgtype__", None)
        if msgtype is not None:  # already a rosbags message: convert directly
            return self._emit(topic, msgtype, msg, recv_ns)
        from rclpy.serialization import serialize_message  # only a ROS 2 program has rclpy

        return self.feed_cdr(topic, ros2_msgtype(type(msg)), serialize_message(msg), recv_ns)

    def _emit(self, topic: str, msgtype: str, msg: Any, recv_ns: int | None) -> SourceMessage:
        stamp = message_stamp_ns(msg) if self._header_clock else 0
        stamp = stamp or (recv_ns if recv_ns is not None else self._clock_ns())
        item = SourceMessage(topic, stamp, self._converter.to_json(msg), msgtype)
        with self._lock:
            self._sink(item)
            self.count += 1
        return item


def ros2_msgtype(cls: type) -> str:
    """The ROS type name (nav_msgs/msg/Odometry) of an rclpy message class."""
    parts = cls.__module__.split(".")
    if len(parts) < 2 or parts[1] not in ("msg", "srv", "action"):
        name = f"{cls.__module__}.{cls.__qualname__}"
        raise InvalidInputError(f"{name} is not a ROS 2 message class.")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


class JsonlSink:
    """A sink that appends each message to a JSONL file (flushed every `flush_every`)."""

    def __init__(self, path: str | Path, *, flush_every: int = 100) -> None:
        self._file: TextIO = open(path, "a", encoding="utf-8")
        self._flush_every = flush_every
        self._pending = 0

    def __call__(self, m: SourceMessage) -> None:
        self._file.write(format_line(m.topic, m.stamp_ns, m.text))
        self._pending += 1
        if self._pending >= self._flush_every:
            self._file.flush()
            self._pending = 0

    def close(self) -> None:
        self._file.close()
