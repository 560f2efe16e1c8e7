"""Export windows to an MCAP file any MCAP tool (Foxglove, `mcap` CLI) can open.

One channel per stream with `message_encoding` "json" and a "jsonschema" schema; each
message's bytes are the stored JSON text unchanged, `log_time` and `publish_time` its
stamp. Each window becomes a Metadata record named `cclogfs.window` (MCAP metadata
values are strings, so `meta` is its JSON text).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path

from mcap.writer import CompressionType, Writer

from ..errors import InvalidInputError
from .base import ExportStats, Progress, StoredWindow
from .jsonschema import message_schema

WINDOW_METADATA = "cclogfs.window"
_COMPRESSION = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}


def export_mcap(
    windows: Iterable[StoredWindow],
    path: str | Path,
    *,
    compression: str = "zstd",
    progress: Progress | None = None,
) -> ExportStats:
    """Write every window's messages to `path` (replaced atomically when complete)."""
    try:
        comp = _COMPRESSION[compression]
    except KeyError:
        raise InvalidInputError(
            f"Unknown MCAP compression {compression!r}; use one of {', '.join(_COMPRESSION)}."
        ) from None
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    stats = ExportStats(files=[str(path)])
    try:
        _write(windows, tmp, comp, stats, progress)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
    return stats


def _write(
    windows: Iterable[StoredWindow], tmp: Path, comp: CompressionType, stats: ExportStats,
    progress: Progress | None,
) -> None:
    channels: dict[str, int] = {}
    sequence: dict[int, int] = {}
    with open(tmp, "wb") as f:
        writer = Writer(f, compression=comp)
        writer.start(profile="", library="cclogfs")
        for w in windows:
            count = 0
            for stamp_ns, text in w.messages():
                if stamp_ns < 0:
                    raise InvalidInputError(
                        f"The message on {w.name} at {stamp_ns} ns cannot go into MCAP, whose "
                        "times are unsigned nanoseconds; export a time range after 0 (--start 0)."
                    )
                chan = channels.get(w.name)
                if chan is None:
                    chan = channels[w.name] = _register(writer, w, text)
                seq = sequence[chan] = sequence.get(chan, -1) + 1
                writer.add_message(
                    chan,
                    log_time=stamp_ns,
                    publish_time=stamp_ns,
                    data=text.encode("utf-8"),
                    sequence=seq & 0xFFFFFFFF,
                )
                count += 1
            writer.add_metadata(WINDOW_METADATA, window_metadata(w, count))
            stats.windows += 1
            stats.messages += count
            stats.streams.add(w.name)
            if progress is not None:
                progress(count)
        writer.finish()
        f.flush()
        os.fsync(f.fileno())


def _register(writer: Writer, w: StoredWindow, first_text: str) -> int:
    # The ROS type names the schema when the recorder kept it; else the stream does.
    title = str(w.meta.get("msgtype") or w.name)
    schema = writer.register_schema(title, "jsonschema", message_schema(first_text, title))
    return writer.register_channel(w.name, "json", schema)


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
