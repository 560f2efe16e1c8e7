"""Serve a store's messages over the Foxglove WebSocket protocol: `cclog play --foxglove`.

The official `foxglove-sdk` runs the server; each stream is a channel with JSON messages
and a JSON Schema whose name is the stream's ROS type (`nav_msgs/msg/Odometry`) when the
store kept it, so the Foxglove app's panels know what they are looking at. The server also
broadcasts each message's stamp as its time, so the app's clock follows the playback.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from ..errors import InvalidInputError
from ..export.jsonschema import message_schema


class FoxgloveServer:
    """One channel per stream; `publish(stream, stamp_ns, text)` logs a message to it."""

    def __init__(self, store: Any, names: list[str], types: dict[str, dict[str, Any]], *,
                 host: str = "127.0.0.1", port: int = 8765) -> None:  # fmt: skip
        try:
            import foxglove
        except ImportError as err:
            raise InvalidInputError(f"--foxglove needs the foxglove-sdk package (pip install foxglove-sdk): {err}") from None
        self._subscribed: set[int] = set()
        self._cond = threading.Condition()

        outer = self

        class Listener(foxglove.ServerListener):
            def on_subscribe(self, client: Any, channel: Any) -> None:
                with outer._cond:
                    outer._subscribed.add(channel.id)
                    outer._cond.notify_all()

        self.channels: dict[str, Any] = {}
        for name in names:
            first = next((text for w in store.query(name) for _, text in w.messages()), None)
            if first is None:
                continue
            title = types.get(name, {}).get("msgtype") or name
            schema = foxglove.Schema(name=title, encoding="jsonschema", data=message_schema(first, title))
            self.channels[name] = foxglove.Channel(name, schema=schema, message_encoding="json")
        try:
            self.server = foxglove.start_server(name="cclog play", host=host, port=port, server_listener=Listener(),
                                                capabilities=[foxglove.Capability.Time])  # fmt: skip
        except Exception as err:  # the SDK raises its own error type for a port in use
            raise InvalidInputError(f"cannot serve Foxglove on {host}:{port}: {err}") from None
        self.port = self.server.port
        self.published = 0

    def wait_for_subscribers(self, timeout: float | None = None) -> bool:
        """Block until a client has subscribed to every channel (False on timeout)."""
        want = {c.id() for c in self.channels.values()}
        with self._cond:
            return self._cond.wait_for(lambda: want <= self._subscribed, timeout)

    def publish(self, name: str, stamp_ns: int, text: str) -> None:
        channel = self.channels.get(name)
        if channel is None:
            return
        self.server.broadcast_time(stamp_ns)
        channel.log(text.encode("utf-8"), log_time=stamp_ns)
        self.published += 1

    def close(self, linger_s: float = 0.5) -> None:
        time.sleep(linger_s)  # let the server send what is queued
        for channel in self.channels.values():
            channel.close()
        self.server.stop()
