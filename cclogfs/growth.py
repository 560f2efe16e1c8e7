"""What of a source file's start stays the same while its writer goes on: a run's fingerprint
keeps its SHA-256 as `head`, so that the file is known again once it has grown
(`runs.grown_run`) and its first messages are not stored twice.

For most files that is simply their first bytes (a JSONL log is appended to, an MCAP file
written in writing order). Two formats rewrite their start when they close or grow:

- A ROS 1 bag: its bag header record (offset 13, 4 KiB) holds the index position and the
  connection and chunk counts, written as 0 until the bag is closed. Its head is the
  records after it that were complete, up to the first unfinished one: a chunk still
  open (rosbag's recorder writes a chunk's header with size 0 and fills it in when it
  closes the chunk), or one cut by the end of what was seen.
- A ROS 2 bag's single `.db3` file (sqlite): the database header counts changes and pages,
  and rows move between pages as the tables grow. Its head is its first message row (the
  topic's name and type, the stamp and the serialized bytes), the start of the recording.
"""

from __future__ import annotations

import os
import struct

EDGE = 1 << 20  # a head spans at most the file's first MiB: cheap on a 10 GB bag

_ROSBAG1 = b"#ROSBAG V2.0\n"
_SQLITE = b"SQLite format 3\x00"
_U32 = struct.Struct("<I")
_CHUNK_OP = b"op=\x05"


def head(path: str, seen: int) -> str | None:
    """The SHA-256 (hex) of what of the file `path` stays the same as it grows, judged on
    its first `seen` bytes (the size an earlier run saw; its own size for a fingerprint).
    None when nothing of it is known to stay (a bag with no complete record, a .db3
    without messages or that sqlite cannot read)."""
    import hashlib  # here: every reader imports `runs`, and this, for `hidden_by_default`

    with open(path, "rb") as f:
        magic = f.read(len(_SQLITE))
        if magic.startswith(_ROSBAG1):
            span = _rosbag1_span(f, min(seen, EDGE))
            if span is None:
                return None
            f.seek(span[0])
            return hashlib.sha256(f.read(span[1] - span[0])).hexdigest()
        if magic == _SQLITE:
            return _db3_head(path)
        f.seek(0)
        return hashlib.sha256(f.read(min(seen, EDGE))).hexdigest()


def _rosbag1_span(f, limit: int) -> tuple[int, int] | None:
    """(start, end) of the complete records after the bag header record within the first
    `limit` bytes, up to an open chunk; None when there is none. A record is a header
    length, the header, a data length and the data (all lengths u32 little-endian)."""
    pos, start = len(_ROSBAG1), None
    while True:
        f.seek(pos)
        raw = f.read(_U32.size)
        if len(raw) < _U32.size:
            break
        (header_len,) = _U32.unpack(raw)
        if pos + 2 * _U32.size + header_len > limit:
            break
        header = f.read(header_len)
        raw = f.read(_U32.size)
        if len(header) < header_len or len(raw) < _U32.size or b"op=" not in header:
            break  # cut, or not a record (every record's header names its op): no more
        end = pos + 2 * _U32.size + header_len + _U32.unpack(raw)[0]
        if end > limit:
            break
        if start is None:
            start = end  # past the bag header record, rewritten when the bag closes
        elif end == pos + 2 * _U32.size + header_len and _CHUNK_OP in header:
            break  # a chunk still open: its sizes are filled in when it closes
        pos = end
    return None if start is None or pos == start else (start, pos)


def _db3_head(path: str) -> str | None:
    """The SHA-256 of a .db3's first message row with its topic's name and type."""
    import sqlite3

    try:
        db = sqlite3.connect(f"file:{os.path.abspath(path)}?mode=ro", uri=True)
        try:
            row = db.execute("SELECT t.name, t.type, m.timestamp, m.data FROM messages m JOIN topics t "
                             "ON t.id = m.topic_id ORDER BY m.id LIMIT 1").fetchone()  # fmt: skip
        finally:
            db.close()
    except sqlite3.Error:
        return None
    if row is None:
        return None
    import hashlib

    h = hashlib.sha256()
    for text in row[:2]:
        h.update(str(text).encode() + b"\0")
    h.update(int(row[2]).to_bytes(8, "little", signed=True))
    h.update(bytes(row[3]))
    return h.hexdigest()
