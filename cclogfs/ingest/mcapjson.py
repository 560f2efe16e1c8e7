"""Plain MCAP files whose channels carry JSON (`message_encoding` "json"), through `mcap`.

Such files are what `cclog export --mcap` writes and what many non-ROS loggers produce.
The message bytes are the JSON text, so it is passed on unchanged.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import BinaryIO

from mcap.reader import make_reader

from ..errors import SourceError
from ..jsontext.rostypes import TypeCheck
from .base import BadMessages, OnError, SourceMessage, topic_filter


def mcap_encodings(path: str | Path) -> set[str]:
    """The message encodings of an MCAP file's channels (from its summary, else a full scan)."""
    try:
        f = open(path, "rb")
    except OSError as err:
        raise SourceError(f"Cannot read {path}: {err.strerror or err}.") from err
    with f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None:
                return {c.message_encoding for c in summary.channels.values()}
            return {ch.message_encoding for _, ch, _ in reader.iter_messages(log_time_order=False)}
        except Exception as err:  # mcap raises its own, struct and OS errors for a damaged file
            raise SourceError(f"{path} is not a readable MCAP file: {err}") from err


class McapJsonSource:
    """Messages of an MCAP file with JSON channels, in log-time order.

    `stamp_ns` is the message's log time; `msgtype` the channel's schema name.
    """

    def __init__(self, path: str | Path, *, topics: Iterable[str] | None = None, on_error: OnError = "stop",
                 report: Callable[[SourceError], None] | None = None, types: TypeCheck | None = None) -> None:  # fmt: skip
        self.name = str(path)
        self._bad = BadMessages(on_error, report)  # a message `types` refuses (another type than its topic's first...)
        self._types = types
        self._wanted = topic_filter(topics)
        try:
            self._file: BinaryIO = open(path, "rb")
        except OSError as err:
            raise SourceError(f"Cannot open {self.name}: {err.strerror or err}.") from err

    def __enter__(self) -> McapJsonSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._file.close()

    @property
    def skipped(self) -> int:
        """Bad messages skipped (on_error="skip")."""
        return self._bad.skipped

    def topics(self) -> dict[str, str]:
        self._file.seek(0)
        summary = make_reader(self._file).get_summary()
        if summary is None:
            return {}
        return {
            ch.topic: summary.schemas[ch.schema_id].name if ch.schema_id else ""
            for ch in summary.channels.values()
            if self._wanted is None or ch.topic in self._wanted
        }

    def __iter__(self) -> Iterator[SourceMessage]:
        self._file.seek(0)
        topics = None if self._wanted is None else sorted(self._wanted)
        types = self._types if self._types is not None else TypeCheck()
        try:
            for index, (schema, channel, message) in enumerate(make_reader(self._file).iter_messages(topics=topics), 1):
                if channel.message_encoding != "json":
                    raise SourceError(
                        f"{self.name}: channel {channel.topic} has message encoding "
                        f"{channel.message_encoding!r}; only 'json' is read this way."
                    )
                try:
                    text = message.data.decode("utf-8")
                    json.loads(text)
                except ValueError as err:
                    raise SourceError(
                        f"{self.name}: the message on {channel.topic} logged at "
                        f"{message.log_time} ns is not valid JSON: {err}"
                    ) from err
                msgtype = schema.name if schema is not None else ""
                if (why := types.mismatch(channel.topic, msgtype)) is not None:
                    self._bad(SourceError(f"{self.name}, message {index:,} (logged at {message.log_time} ns): {why}"))
                    continue
                yield SourceMessage(channel.topic, message.log_time, text, msgtype)
        except SourceError:
            raise
        except Exception as err:
            raise SourceError(f"{self.name}: reading the MCAP file failed: {err}") from err
