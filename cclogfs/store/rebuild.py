"""A damaged MANIFEST rebuilt from the segment files (`fsck --repair` only).

The manifest is the store's catalogue, but every record names its seq and stream, and every
segment file its first seq and the manifest generation it was made under: the catalogue can
be derived again. What cannot be is kept aside: the damaged MANIFEST goes to quarantine, the
store gets a new id, and retention's running totals (`dropped`) start again at zero.
"""

from __future__ import annotations

import os
import time
import uuid
from typing import Any

from .format import (
    FORMAT_VERSION,
    MANIFEST,
    QUARANTINE,
    SEGMENT_HEADER_SIZE,
    parse_seq_name,
    segment_manifest_gen,
    unpack_segment_header,
)
from .fs import FileSystem
from .index import SegmentIndex
from .manifest import Manifest
from .segment import open_segment, scan


def rebuild_manifest(fs: FileSystem, path: str, codec_config: dict[str, Any]) -> list[str]:
    """Write a new MANIFEST from the segment files, the damaged one moved to quarantine;
    what was done, as lines for the repair report."""
    chosen = _chosen_segments(fs, path)
    infos, gen_seen, created = [], 0, time.time_ns()
    for (first_seq, gen, name), after in zip(chosen[:-1], chosen[1:]):  # the newest stays the tail
        info, seg_gen = _sealed_info(fs, os.path.join(path, name), first_seq, gen, after[0])
        infos.append(info)
        gen_seen = max(gen_seen, seg_gen)
    for _first, _gen, name in chosen[-1:]:
        fd = fs.open(os.path.join(path, name))
        try:
            head = fs.pread(fd, SEGMENT_HEADER_SIZE, 0)  # a segment may be gigabytes: its header only
        finally:
            fs.close(fd)
        gen_seen = max(gen_seen, segment_manifest_gen(head))
        parsed = unpack_segment_header(head)
        created = parsed[1] if parsed else created
    quarantine = []
    if fs.exists(os.path.join(path, MANIFEST)):  # damaged: kept aside (a missing one has nothing to keep)
        quarantine.append(f"{MANIFEST}.damaged-{time.time_ns()}")
        fs.mkdir(os.path.join(path, QUARANTINE))
        fs.rename(os.path.join(path, MANIFEST), os.path.join(path, QUARANTINE, quarantine[0]))
        fs.fsync_dir(os.path.join(path, QUARANTINE))
    first = chosen[0][0] if chosen else 0
    body = {"format_version": FORMAT_VERSION, "store_id": uuid.uuid4().hex, "created_ns": created,
            "codec": codec_config, "segments": infos, "first_seq": first, "generation": gen_seen + 1,
            "quarantine": quarantine}  # fmt: skip
    Manifest(body).commit(fs, os.path.join(path, MANIFEST))
    old = f"the damaged one is {QUARANTINE}/{quarantine[0]}" if quarantine else f"it was missing"
    return [f"rebuilt {MANIFEST} from {len(chosen)} segment files (new store id; retention's totals start "
            f"again; {old})"]  # fmt: skip


def _chosen_segments(fs: FileSystem, path: str) -> list[tuple[int, int, str]]:
    """(first_seq, gen, name) per first seq, in seq order: the newest generation whose
    file scans to its end (an interrupted compaction's may not)."""
    by_first: dict[int, list[tuple[int, str]]] = {}
    for name in fs.listdir(path):
        parsed = parse_seq_name(name)
        if parsed and parsed[1] == "seg":
            by_first.setdefault(parsed[0], []).append((parsed[2], name))
    chosen = []
    for first_seq in sorted(by_first):
        gens = sorted(by_first[first_seq], reverse=True)
        pick = next((g for g in gens if _scans_whole(fs, os.path.join(path, g[1]), first_seq)), gens[-1])
        chosen.append((first_seq, *pick))
    return chosen


def _scans_whole(fs: FileSystem, file: str, first_seq: int) -> bool:
    seg, ok = open_segment(fs, file, write=False)
    try:
        return ok and seg.first_seq == first_seq and scan(seg).problem is None
    finally:
        fs.close(seg.fd)


def _sealed_info(fs: FileSystem, file: str, first_seq: int, gen: int, end_seq: int) -> tuple[dict[str, Any], int]:
    """The manifest entry of a sealed segment ending where the next begins (`end_seq`)."""
    seg, _ok = open_segment(fs, file, write=False)
    seg.first_seq = first_seq
    try:
        result = scan(seg, salvage=True)
        head = fs.pread(seg.fd, SEGMENT_HEADER_SIZE, 0)
    finally:
        fs.close(seg.fd)
    damage = [*result.damage, *([result.problem] if result.problem else [])]
    for p in damage:
        lost = p.put_end[1] if p.put_end else 0  # an unfinished put's parts run to the end
        p.seqs = p.seqs or (result.next_seq, max(end_seq, result.next_seq, lost))
    info = {"first_seq": first_seq, "end_seq": max(end_seq, result.next_seq, *(p.seqs[1] for p in damage)), "size": seg.size, "gen": gen,
            "streams": SegmentIndex.build(result.rows).stream_stats(), "aged": result.aged}  # fmt: skip
    if damage:
        info["damaged"] = [p.damage_info() for p in damage]
    return info, segment_manifest_gen(head)
