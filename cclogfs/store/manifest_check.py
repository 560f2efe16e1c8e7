"""Every field of a MANIFEST body checked (types and ranges) before any is acted on.

A body whose CRC holds can still be forged or written by a buggy tool: a `first_seq` past
the segments once made the writer delete the active segment as a leftover, and a huge
`end_seq` made readers skip the active records and the writer crash. So the body is
checked whole, here, and a body that fails is a damaged MANIFEST (`bad record field`,
naming the field), which `cclog fsck --repair` rebuilds from the segment files.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from .format import MAX_NS, MIN_NS, SEGMENT_HEADER_SIZE, SIDE_FILE, Reason, RecordError

U64_END = 1 << 64  # seqs are u64: one past the last is at most this
MAX_GEN = 10**10 - 1  # a generation names files with at most ten digits (FORMAT.md)
MAX_MANIFEST_GEN = (1 << 32) - 1  # segment headers state it as u32
STAT_KEYS = ("windows", "messages", "start_ns", "end_ns", "raw_bytes", "stored_bytes")
_QUARANTINED_MANIFEST = re.compile(r"^MANIFEST\.damaged-\d+$")


def _fail(field: str, value: Any, want: str) -> RecordError:
    shown = repr(value)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    return RecordError(Reason.BAD_FIELD, f"field {field} is {shown}, expected {want}")


def _int(body: Mapping[str, Any], key: str, field: str, lo: int, hi: int, default: int | None = None) -> int:
    value = body.get(key, default)
    if type(value) is not int or not lo <= value <= hi:  # bool is not an int here
        raise _fail(field, value, f"an integer in {lo}..{hi}")
    return value


def _dict(value: Any, field: str) -> Mapping[str, Any]:
    if not isinstance(value, dict):
        raise _fail(field, value, "an object")
    return value


def _list(value: Any, field: str) -> list[Any]:
    if not isinstance(value, list):
        raise _fail(field, value, "a list")
    return value


def check_stats(stats: Any, field: str) -> None:
    """Per-stream statistics: {name: {windows, messages, start_ns, end_ns, raw_bytes, stored_bytes}}."""
    for name, st in _dict(stats, field).items():
        where = f"{field}[{name!r}]"
        st = _dict(st, where)
        for key in STAT_KEYS:
            lo, hi = (MIN_NS, MAX_NS) if key.endswith("_ns") else (0, MAX_NS)
            _int(st, key, f"{where}.{key}", lo, hi)
        if st["start_ns"] > st["end_ns"]:
            raise _fail(f"{where}.end_ns", st["end_ns"], f"at least start_ns {st['start_ns']}")


def _check_damage(entries: Any, field: str, size: int) -> None:
    # A segment cut short since sealing (FORMAT.md) states its size now, and its cut is a
    # stretch from the end of its last intact record (the header's end when the cut took
    # the header) over the bytes it lost: past the file, as long as they were.
    for i, d in enumerate(_list(entries, field)):
        where = f"{field}[{i}]"
        d = _dict(d, where)
        _int(d, "offset", f"{where}.offset", 0, max(size, SEGMENT_HEADER_SIZE))
        _int(d, "length", f"{where}.length", 0, MAX_NS)
        first = _int(d, "first_seq", f"{where}.first_seq", 0, U64_END)
        _int(d, "end_seq", f"{where}.end_seq", first, U64_END)
        if not isinstance(d.get("reason"), str):
            raise _fail(f"{where}.reason", d.get("reason"), "a string")


def _check_segment(info: Any, i: int, expect_first: int | None) -> int:
    """One `segments[i]` entry; returns its end_seq."""
    where = f"segments[{i}]"
    info = _dict(info, where)
    first = _int(info, "first_seq", f"{where}.first_seq", 0, U64_END - 1)
    if expect_first is not None and first != expect_first:
        raise _fail(f"{where}.first_seq", first, f"{expect_first}, where the segment before it ends")
    end = _int(info, "end_seq", f"{where}.end_seq", first, U64_END - 1)
    size = _int(info, "size", f"{where}.size", 0, MAX_NS)  # a cut segment may have lost its header
    _int(info, "gen", f"{where}.gen", 0, MAX_GEN, default=0)
    check_stats(info.get("streams"), f"{where}.streams")
    for name, n in _dict(info.get("aged", {}), f"{where}.aged").items():
        if type(n) is not int or n < 0:
            raise _fail(f"{where}.aged[{name!r}]", n, "a count >= 0")
    for key in ("damaged", "discarded"):
        _check_damage(info.get(key, []), f"{where}.{key}", size)
    return end


def _check_quarantine(names: Any) -> None:
    # The names become paths (repair deletes them): only a side file or a damaged MANIFEST.
    for i, name in enumerate(_list(names, "quarantine")):
        if not isinstance(name, str) or not (SIDE_FILE.match(name) or _QUARANTINED_MANIFEST.match(name)):
            raise _fail(f"quarantine[{i}]", name, "a side file or MANIFEST.damaged-N name")


def body_version(body: Any) -> int:
    """The body's `format_version` (an integer: which versions this cclogfs reads is the
    caller's question)."""
    return _int(_dict(body, "body"), "format_version", "format_version", 0, MAX_NS)


def check_body(body: Any) -> None:
    """Raise RecordError (`bad record field`, naming the field) unless every field of a
    manifest body has the type and range FORMAT.md gives it. `format_version` is checked
    by the caller first: a newer version may hold what this one does not know."""
    body = _dict(body, "body")
    if not isinstance(body.get("store_id"), str):
        raise _fail("store_id", body.get("store_id"), "a string")
    _int(body, "created_ns", "created_ns", MIN_NS, MAX_NS)
    _dict(body.get("codec"), "codec")
    segments = _list(body.get("segments"), "segments")
    first = _int(body, "first_seq", "first_seq", 0, U64_END - 1, default=0)
    end = first
    for i, info in enumerate(segments):
        end = _check_segment(info, i, first if i == 0 else end)
    _int(body, "generation", "generation", 0, MAX_MANIFEST_GEN, default=0)
    dropped = _dict(body.get("dropped", {"segments": 0, "streams": {}}), "dropped")
    _int(dropped, "segments", "dropped.segments", 0, U64_END)
    check_stats(dropped.get("streams"), "dropped.streams")
    mark = _dict(body.get("checkpoint", {}), "checkpoint")
    if mark:
        cp_first = _int(mark, "first_seq", "checkpoint.first_seq", 0, U64_END - 1)
        _int(mark, "synced", "checkpoint.synced", 0, MAX_NS)
        _int(mark, "next_seq", "checkpoint.next_seq", cp_first, U64_END)
        if "xxh3" in mark:  # a digest is a u64 (absent from what older versions wrote)
            _int(mark, "xxh3", "checkpoint.xxh3", 0, U64_END - 1)
    _check_quarantine(body.get("quarantine", []))
