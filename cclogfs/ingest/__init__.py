"""Log sources: ROS 1 and ROS 2 bags, MCAP files and JSON Lines, all as `SourceMessage`s.

`open_source(path)` looks at the file (magic bytes, MCAP channel encodings) and picks a
class from `FORMATS`; every class follows the `Source` protocol. Parsing is left to
`rosbags` and `mcap`; this package only maps their messages to rosbridge JSON.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Callable, Iterable
from importlib import import_module
from pathlib import Path

from ..errors import SourceError
from ..jsontext.lines import format_line, parse_line
from ..jsontext.rostypes import TypeCheck
from .base import OnError, Source, SourceMessage, check_clock
from .jsonl import JsonlSource

__all__ = [
    "FORMATS",
    "JsonlSource",
    "McapJsonSource",
    "RosbagSource",
    "Source",
    "SourceMessage",
    "detect_format",
    "format_line",
    "open_source",
    "parse_line",
]

# format -> (module, class). A reader is imported when a source of its format is opened:
# rosbags and mcap take longer to import than recording a short JSONL stream.
_READERS = {
    "rosbag1": ("rosbag", "RosbagSource"),
    "rosbag2": ("rosbag", "RosbagSource"),
    "mcap-json": ("mcapjson", "McapJsonSource"),
    "jsonl": ("jsonl", "JsonlSource"),
}


def _reader(fmt: str) -> type[Source]:
    module, name = _READERS[fmt]
    return getattr(import_module(f".{module}", __name__), name)


def __getattr__(name: str):
    if name == "FORMATS":  # {format: reader class}, importing every reader
        return {fmt: _reader(fmt) for fmt in _READERS}
    if name in ("RosbagSource", "McapJsonSource"):
        return _reader("rosbag1" if name == "RosbagSource" else "mcap-json")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

_MAGIC_ROSBAG1 = b"#ROSBAG V2.0\n"
_MAGIC_MCAP = b"\x89MCAP0\r\n"
_MAGIC_SQLITE = b"SQLite format 3\x00"
# rosbags picks its storage plugin by file name, so these must carry the right suffix.
_SUFFIX = {"rosbag1": ".bag", "mcap": ".mcap", "sqlite3": ".db3"}


def _refuse_store(p: Path) -> None:
    """A cclogfs store given as a source was "not a ROS 2 bag", which told nothing of
    what it is, nor how to read it."""
    from ..store.format import MANIFEST

    if (p / MANIFEST).is_file():
        raise SourceError(f"{p} is a cclogfs store, not a recording: read its messages with `cclog cat {p}` (JSON "
                          f"lines, which `cclog record -` takes) or `cclog export {p} --mcap OUT.mcap`.")  # fmt: skip


def detect_format(path: str | Path) -> str:
    """The key in FORMATS for `path` ("-" is standard input, read as JSONL)."""
    if str(path) == "-":
        return "jsonl"
    p = Path(path)
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return "rosbag2"
        if any(p.glob("*.db3")):
            return "rosbag2"  # never indexed: the bag reader refuses it, then ingest.ros2salvage reads it
        _refuse_store(p)
        raise SourceError(f"{p} is a directory without metadata.yaml, so not a ROS 2 bag.")
    try:
        with open(p, "rb") as f:
            head = f.read(64)
    except OSError as err:
        raise SourceError(f"Cannot read {p}: {err.strerror or err}.") from err
    if head.startswith(_MAGIC_ROSBAG1):
        _need_suffix(p, "rosbag1", "a ROS 1 bag")
        return "rosbag1"
    if head.startswith(_MAGIC_SQLITE):
        _need_suffix(p, "sqlite3", "a SQLite database (ROS 2 bag storage)")
        return "rosbag2"
    if head.startswith(_MAGIC_MCAP):
        return _mcap_format(p)
    if head.lstrip()[:1] == b"{" or (not head.startswith(b"\xef\xbb\xbf") and p.suffix in (".jsonl", ".ndjson")):
        return "jsonl"  # by name too: a log cut at its start begins mid-line, which the reader names
    if head.startswith(b"\xef\xbb\xbf") and head[3:].lstrip()[:1] == b"{":  # was "of an unknown file type"
        raise SourceError(f"{p} starts with a UTF-8 byte order mark, which JSON Lines does not allow (nor does "
                          "Python's json); remove those 3 bytes (sed -i '1s/^\\xEF\\xBB\\xBF//' FILE).")  # fmt: skip
    raise SourceError(
        f"{p} is of an unknown file type: not a ROS 1 bag, ROS 2 bag, MCAP or JSON Lines file."
    )


def _mcap_format(p: Path) -> str:
    from .mcapjson import mcap_encodings

    try:
        encodings = mcap_encodings(p)
    except SourceError:
        if p.suffix != _SUFFIX["mcap"]:
            raise
        return "rosbag2"  # damaged: the bag reader refuses it, then ingest.salvage reads what it can
    if encodings <= {"json"}:
        return "mcap-json"
    if encodings == {"cdr"}:
        _need_suffix(p, "mcap", "a ROS 2 MCAP file")
        return "rosbag2"
    raise SourceError(
        f"{p} is an MCAP file with message encodings {sorted(encodings)}; "
        "only all-'cdr' (ROS 2) or all-'json' files can be read."
    )


def _need_suffix(p: Path, kind: str, what: str) -> None:
    if p.suffix != _SUFFIX[kind]:
        raise SourceError(
            f"{p} is {what} but its name does not end in {_SUFFIX[kind]}, which the bag "
            "reader needs; rename it (or link it) with that suffix."
        )


def open_source(
    path: str | Path,
    topics: Iterable[str] | None = None,
    *,
    format: str | None = None,
    on_error: OnError = "stop",
    report: Callable[[SourceError], None] | None = None,
    clock: str = "log",
    max_text_bytes: int | None = None,
    types: TypeCheck | None = None,
) -> Source:
    """Open a log for reading, choosing the reader by file type (or by `format`). `clock`:
    the time of a bag's messages, "log" or "header" (JSONL lines and JSON MCAP carry their
    own times, so for them only "log" is accepted). `max_text_bytes`: a JSONL line whose
    message is longer is a bad line (named, or skipped with on_error="skip"), as is a message of
    another type than its topic's first in any source (a stream keeps one type). `types`:
    the check of each message's topic and type (`TypeCheck`), to refuse reserved topics and
    types other than a store's (the salvage readers of damaged files do not take it)."""
    fmt = format or detect_format(path)
    if fmt not in _READERS:
        raise SourceError(
            f"Unknown source format {fmt!r} for {path}; known: {', '.join(sorted(_READERS))}."
        ) from None
    check_clock(clock)
    if fmt == "jsonl":
        _log_clock_only(path, clock)
        return JsonlSource(path, topics=topics, on_error=on_error, report=report, max_text_bytes=max_text_bytes,
                          types=types)
    if not Path(path).exists():
        raise SourceError(f"{path} does not exist.")
    cls = _reader(fmt)  # imported only now: rosbags and mcap are slow to import
    if fmt in ("rosbag1", "rosbag2"):
        try:
            if fmt == "rosbag2" and _db3_cut_short(Path(path)):
                raise SourceError("its database is cut short")  # the bag reader would fail midway
            if fmt == "rosbag2" and (why := mcap_summary_damaged(Path(path))):
                raise SourceError(why)  # the bag reader would trust its schemas and channels
            return cls(path, topics=topics, clock=clock, on_error=on_error, report=report, types=types)
        except SourceError as err:
            salvage = _salvage_class(fmt, Path(path))
            if salvage is None:
                raise
            return salvage(path, topics=topics, clock=clock, why=str(err))
    _log_clock_only(path, clock)
    return cls(path, topics=topics, on_error=on_error, report=report, types=types)


def _salvage_class(fmt: str, p: Path):
    """The reader of what can be read of a damaged file of this kind (None: none)."""
    from .ros2salvage import Ros2DbSalvage
    from .salvage import McapSalvage, Ros1Salvage

    if fmt == "rosbag1":
        return Ros1Salvage
    if p.suffix == _SUFFIX["sqlite3"] or (p.is_dir() and any(p.glob("*.db3"))):
        return Ros2DbSalvage
    if p.is_file() and p.suffix == _SUFFIX["mcap"]:
        return McapSalvage
    return None


def _db3_cut_short(p: Path) -> bool:
    from .ros2salvage import db3_cut_short, db3_files

    return any(f.suffix == _SUFFIX["sqlite3"] and db3_cut_short(f) for f in db3_files(p))


def mcap_summary_damaged(p: Path) -> str | None:
    """Why the summary section of the MCAP file `p` cannot be trusted (None: it can, or it
    has no CRC). The bag reader takes the schemas and channels from the summary, which no
    chunk CRC covers: a flipped byte there renamed a field or a topic of every message, read
    without a word (exit 0). The footer's summary_crc covers it (the MCAP spec, "Footer")."""
    if not (p.is_file() and p.suffix == _SUFFIX["mcap"]):
        return None
    with open(p, "rb") as f:
        size = f.seek(0, os.SEEK_END)
        if size < 8 + 37:
            return None  # too short for a footer: the reader says what is wrong
        f.seek(size - 37)
        tail = f.read(37)
        if tail[0] != 0x02:  # no footer where it belongs: the reader says so, or salvage reads it
            return None
        _length, start, _offsets, crc = struct.unpack("<QQQI", tail[1:29])
        if not crc or not 0 < start <= size - 37:
            return None
        f.seek(start)
        got = zlib.crc32(f.read(size - 12 - start))
    if got != crc:
        return (f"its summary section (offset {start} to the footer at {size - 37}) fails its CRC "
                f"(footer says {crc:#010x}, the bytes give {got:#010x}): damaged")
    return None


def _log_clock_only(path: str | Path, clock: str) -> None:
    if clock != "log":
        raise SourceError(f"{path}: --clock {clock} needs a ROS bag or ROS 2 MCAP; this source carries its own "
                          "times (JSONL stamp_ns, JSON MCAP log time).")  # fmt: skip
