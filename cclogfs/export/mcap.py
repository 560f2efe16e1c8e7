"""Export windows to an MCAP file any MCAP tool (Foxglove, `mcap` CLI) can open.

One channel per stream. With encoding "auto" (the default) a stream whose ROS type rosbags
knows is written as `ros2 bag record` writes it: `cdr` messages, a `ros2msg` schema named
after the type (`export.ros2cdr`); any other stream as `json` messages (the stored text
unchanged) with a "jsonschema" schema, and the caller is told (`McapStats.json_streams`).
"cdr" refuses a stream it cannot write as CDR; "json" writes every stream as JSON.
`log_time` and `publish_time` are the stored stamps; messages are written in log-time order,
each channel's `sequence` counting them from 0. Each window becomes a Metadata record
named `cclogfs.window` (MCAP metadata values are strings, so `meta` is its JSON text).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

from mcap.writer import CompressionType, Writer

from ..errors import InvalidInputError
from .base import ExportStats, Progress, StoredWindow, commit_work_file, work_file
from .jsonl import continues, merged_runs
from .jsonschema import message_schema
from .ros2cdr import Describe, Ros2Types, message_error, stream_meta

WINDOW_METADATA = "cclogfs.window"
_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}
ENCODINGS = ("auto", "cdr", "json")


@dataclasses.dataclass
class McapStats(ExportStats):
    """ExportStats, plus what a CDR export could not carry as the store has it."""

    json_streams: dict[str, str] = dataclasses.field(default_factory=dict)  # stream -> why JSON
    notes: Counter = dataclasses.field(default_factory=Counter)  # (stream, sentence with {n}) -> messages


def export_mcap(
    windows: Iterable[StoredWindow],
    path: str | Path,
    *,
    compression: str = "zstd",
    encoding: str = "auto",
    progress: Progress | None = None,
    describe: Describe | None = None,
) -> McapStats:
    """Write every window's messages to `path` (replaced atomically when complete).
    `describe(stream)`: what the store knows of a stream's type beyond the window's meta (the
    definition and latching a recording keeps in its first window only, which the selected
    windows may not include)."""
    try:
        comp = _COMPRESSION[compression]
    except KeyError:
        raise InvalidInputError(
            f"Unknown MCAP compression {compression!r}; use one of {', '.join(_COMPRESSION)}."
        ) from None
    if encoding not in ENCODINGS:
        raise InvalidInputError(f"Unknown MCAP encoding {encoding!r}; use one of {', '.join(ENCODINGS)}.")
    path = Path(path)
    stats = McapStats(files=[str(path)])
    channels = _Channels(encoding, stats, describe)
    tmp = work_file(path)
    try:
        _write(windows, tmp, comp, channels, progress)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    commit_work_file(tmp, path)
    if channels.ros2 is not None:
        stats.notes = channels.ros2.notes
    return stats


def _write(
    windows: Iterable[StoredWindow], tmp: Path, comp: CompressionType, channels: _Channels,
    progress: Progress | None,
) -> None:
    """The messages in log-time order, merged across windows (`merged_runs`), so that each
    channel's sequence numbers increase over time as the MCAP spec asks ("unique per channel
    and increasing over time"): window after window, the numbers went back wherever windows
    of a stream overlap in time (two runs of one source, a smart window that grew back).
    Each window's Metadata record follows, in window order."""
    stats = channels.stats
    read = _Read(windows)
    with open(tmp, "wb") as f:
        writer = Writer(f, compression=comp)
        # The ros2 profile (what rosbag2 writes, and what rosbags requires) unless all JSON.
        writer.start(profile="" if channels.encoding == "json" else "ros2", library="cclogfs")
        for name, run in merged_runs(read):
            if not run:
                continue
            w = read.first[name]  # the stream's first window: its channel's type and schema
            for stamp_ns, text in run:
                if stamp_ns < 0:
                    raise InvalidInputError(
                        f"The message on {name} at {stamp_ns} ns cannot go into MCAP, whose "
                        "times are unsigned nanoseconds; export a time range after 0 (--start 0)."
                    )
                chan, seq, encode = channels.get(writer, w, text)
                try:
                    data = encode(text)
                except InvalidInputError as err:
                    raise message_error(name, seq, stamp_ns, read.record_of(name, stamp_ns), err) from None
                writer.add_message(chan, log_time=stamp_ns, publish_time=stamp_ns, data=data,
                                   sequence=seq & 0xFFFFFFFF)  # fmt: skip
            if progress is not None:
                progress(len(run))
        for done in read.done:
            writer.add_metadata(WINDOW_METADATA, window_metadata(done, done.count))
            stats.wrote(done, done.count)
        writer.finish()
        f.flush()
        os.fsync(f.fileno())


@dataclasses.dataclass
class _Done:
    """What the Metadata record and the counts need of a window whose messages were read
    (not the window: a store window keeps its record once read)."""

    name: str
    seq: int
    start_ns: int
    end_ns: int
    meta: dict
    continues: bool
    count: int = 0


class _Read:
    """The windows handed to the merge, each counted as the merge reads its messages."""

    def __init__(self, windows: Iterable[StoredWindow]) -> None:
        self.windows = windows
        self.first: dict[str, StoredWindow] = {}
        self.done: list[_Done] = []

    def __iter__(self):
        for w in self.windows:
            self.first.setdefault(w.name, w)
            yield _Counted(w, self.done)

    def record_of(self, name: str, stamp_ns: int) -> int | str:
        """The store seq of a window of `name` that holds `stamp_ns`, for an error."""
        for w in (*self.done, *self.first.values()):
            if w.name == name and w.start_ns <= stamp_ns <= w.end_ns:
                return w.seq
        return "?"


class _Counted:
    """A window as `merged_runs` reads it; once its messages are read, its `_Done` joins `done`."""

    def __init__(self, w: StoredWindow, done: list[_Done]) -> None:
        self.w, self.done = w, done
        self.name, self.seq, self.start_ns, self.end_ns = w.name, w.seq, w.start_ns, w.end_ns

    @property
    def continues(self) -> bool:
        return continues(self.w)

    def messages(self):
        w = self.w
        entry = _Done(w.name, w.seq, w.start_ns, w.end_ns, w.meta, continues(w))
        self.done.append(entry)
        for m in w.messages():
            entry.count += 1
            yield m


class _Channels:
    """One channel per stream, its encoding chosen at the stream's first message."""

    def __init__(self, encoding: str, stats: McapStats, describe: Describe | None) -> None:
        self.encoding = encoding
        self.stats = stats
        self.describe = describe
        self.ros2 = Ros2Types() if encoding != "json" else None
        self._chan: dict[str, tuple[int, Callable[[str], bytes]]] = {}
        self._seq: dict[int, int] = {}

    def get(self, writer: Writer, w: StoredWindow, text: str) -> tuple[int, int, Callable[[str], bytes]]:
        """(channel id, the message's sequence number in it, its encoder) for a message of w."""
        entry = self._chan.get(w.name)
        if entry is None:
            entry = self._chan[w.name] = self._register(writer, w, text)
        chan, encode = entry
        seq = self._seq[chan] = self._seq.get(chan, -1) + 1
        return chan, seq, encode

    def _register(self, writer: Writer, w: StoredWindow, first_text: str) -> tuple[int, Callable[[str], bytes]]:
        msgtype = str(w.meta.get("msgtype") or "")
        if self.ros2 is not None:
            meta, why = stream_meta(self.ros2, w, self.describe)
            if why is None:
                name, enc, data = self.ros2.schema(msgtype)
                schema = writer.register_schema(name, enc, data)
                meta = self.ros2.channel_metadata(w.name, msgtype, meta)
                return writer.register_channel(w.name, "cdr", schema, meta), self.ros2.encoder(w.name, msgtype)
            if self.encoding == "cdr":
                raise InvalidInputError(f"{w.name} cannot be exported as CDR: {why}; use --encoding auto or json.")
            self.stats.json_streams[w.name] = why
        # The ROS type names the schema when the recorder kept it; else the stream does.
        title = msgtype or w.name
        schema = writer.register_schema(title, "jsonschema", message_schema(first_text, title))
        return writer.register_channel(w.name, "json", schema), _utf8


def _utf8(text: str) -> bytes:
    return text.encode("utf-8")


def window_metadata(w: StoredWindow, count: int) -> dict[str, str]:
    """The Metadata record fields of one window."""
    return {
        "stream": w.name,
        "seq": str(w.seq),
        "start_ns": str(w.start_ns),
        "end_ns": str(w.end_ns),
        "messages": str(count),
        "meta": json.dumps(w.meta, sort_keys=True),
    }
