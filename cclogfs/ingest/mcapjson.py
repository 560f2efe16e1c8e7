"""Plain MCAP files whose channels carry JSON (`message_encoding` "json"), through `mcap`.

Such files are what `cclog export --mcap` writes and what many non-ROS loggers produce.
The message bytes are the JSON text, so it is passed on unchanged.

An indexed file is read chunk by chunk (`_chunk`), as mcap's reader does, so that a chunk
that cannot be read (CRC, decompression, bytes moved) is named by its byte offset as the
ROS reader names it (`mcapbad`): mcap's reader said "decompression error: Destination
buffer is too small" and nothing of where, and read an uncompressed chunk without checking
its CRC.
"""

from __future__ import annotations

import heapq
import json
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk

from ..errors import SourceError
from ..jsontext.rostypes import TypeCheck
from .base import BadMessages, OnError, SourceMessage, topic_filter
from .mcapbad import BadChunks, channel_counts, not_a_chunk


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
        self._bad_chunks = BadChunks(self.name, on_error)
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

    @property
    def lost(self) -> str | None:
        """What damage lost (chunks skipped with on_error="skip"), None when nothing was."""
        return self._bad_chunks.lost

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
            for index, (schema, channel, message) in enumerate(self._messages(topics), 1):
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

    def _messages(self, topics: list[str] | None) -> Iterator[tuple[Any, Any, Message]]:
        """(schema, channel, message) of `topics` in log-time order, ties in file order (as
        mcap's reader gives them); an indexed file's chunks read one at a time, in the order
        of their first log time, so that a merge holds one chunk per overlap."""
        summary = make_reader(self._file).get_summary()
        if summary is None or not summary.chunk_indexes:  # no index: mcap reads the file linearly
            self._file.seek(0)
            yield from make_reader(self._file, validate_crcs=True).iter_messages(topics=topics)
            return
        chunks = [self._chunk(summary, c, topics) for c in summary.chunk_indexes if _may_hold(summary, c, topics)]
        for *_, item in heapq.merge(*chunks):
            if item is not None:
                yield item

    def _chunk(self, summary: Any, index: Any, topics: list[str] | None) -> Iterator[tuple]:
        """(log time, chunk offset, place, (schema, channel, message)) of one chunk, sorted;
        first its start time alone, so that the merge reads it only when its time comes."""
        offset = index.chunk_start_offset
        yield index.message_start_time, offset, -1, None
        why = not_a_chunk(self._file, index)
        if why is None:
            try:
                records = breakup_chunk(Chunk.read(ReadDataStream(self._file)), validate_crc=True)
            except Exception as err:  # mcap raises its own, zstd/lz4 and struct errors
                why = str(err) or type(err).__name__
        counts = channel_counts(index)  # empty: no message index, nothing to check against
        wanted = {cid for cid, ch in summary.channels.items() if topics is None or ch.topic in topics}
        count = sum(n for cid, n in counts.items() if cid in wanted) if counts else None
        found = []
        if why is None:
            for place, record in enumerate(records):
                if isinstance(record, Message) and record.channel_id in wanted:
                    channel = summary.channels[record.channel_id]
                    found.append((record.log_time, offset, place, (summary.schemas.get(channel.schema_id), channel, record)))
            if count is not None and len(found) != count:
                why = f"it holds {len(found):,} of the {count:,} messages its index counts"
        if why is not None:
            self._bad_chunks(index, why, count)
            return
        found.sort()
        yield from found


def _may_hold(summary: Any, index: Any, topics: list[str] | None) -> bool:
    """Whether the chunk of `index` may hold messages of `topics`: its message indexes
    name its channels; without them (a writer may leave them out) it must be read to know."""
    if topics is None or not index.message_index_offsets:
        return True
    return any(summary.channels[cid].topic in topics for cid in index.message_index_offsets)
