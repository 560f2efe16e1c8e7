"""`fsck --repair`: a sealed segment's damaged 32-byte header written again (FORMAT.md, "Repair").

A segment header holds nothing a record needs: magic, version and flags have one right value,
and first_seq is stated three more times, by the file name, by the manifest and by the first
record's own seq (under its header CRC). When all three agree and every record behind the
header is intact, the header is known and is written again, to a new file renamed over the
old one (the sealed file is never written in place); when they do not, repair keeps the
bytes and says why, rather than guess which one is right.
"""

from __future__ import annotations

import os

from .format import (
    SEGMENT_HEADER,
    SEGMENT_HEADER_SIZE,
    TMP_SUFFIX,
    Reason,
    pack_segment_header,
    segment_header_fault,
)
from .segment import Segment, ends_declared, lost_seqs, scan
from .store import Store


def rebuild_headers(store: Store, actions: list[str], unproven: list[str], *, discarded: bool = False) -> None:
    """Rebuild every sealed segment's damaged header that can be proven; name the others
    in `unproven`. Also forgets the manifest's entry for a header an earlier (interrupted)
    repair rebuilt. `discarded`: after `--discard-damaged`, records in discarded stretches
    (their seqs named as dropped) no longer count against a header: what the store keeps
    then agrees with the name and the manifest."""
    for seg, info in zip(store.sealed, store.manifest.segments):
        name = os.path.basename(seg.path)
        fault = segment_header_fault(store.fs.pread(seg.fd, SEGMENT_HEADER_SIZE, 0)[: seg.size], seg.first_seq)
        if not fault:
            if _header_entries(info):  # rebuilt before a crash stopped that repair: only the entry is left
                _forget_header_damage(store, seg, info)
                actions.append(f"the segment header of {name} is intact (rebuilt by an earlier repair): "
                               "its damage entry is dropped from the manifest")  # fmt: skip
            continue
        # Stretches discarded before (or sealed as discarded: records lost with their header)
        # are gone already, so they never count against a header.
        why = _unprovable(seg, info, seg.known_damage, discarded)
        if why:
            unproven.append(f"{name}: segment header kept as it is, not rebuilt ({fault}): {why}")
            continue
        if seg.size < SEGMENT_HEADER_SIZE:
            _grow_to_header(store, seg)
        _rewrite(store, seg, _new_header(store, seg))
        if _header_entries(info):
            _forget_header_damage(store, seg, info)
        info = next(i for i in store.manifest.segments if i["first_seq"] == seg.first_seq)
        actions.append(f"rebuilt the segment header of {name} ({fault}): first_seq {seg.first_seq}, as "
                       f"{_proof(info)}")  # fmt: skip


def _proof(info: dict) -> str:
    """What vouched for the rebuilt header's first_seq, and what became of the records."""
    gone = [d for d in info.get("discarded", ()) if d["end_seq"] > d["first_seq"]]
    named = [d for d in info.get("damaged", ()) if d["end_seq"] > d["first_seq"]]
    if gone:
        lost = ", ".join(lost_seqs(d["first_seq"], d["end_seq"]) for d in gone)
        said = f"its name and the manifest state (the records that did not agree were discarded: {lost})"
    elif any(d["offset"] == SEGMENT_HEADER_SIZE for d in named):
        said = "its name and the manifest state (its first record is damaged)"
    else:
        said = "its name, the manifest and its first record state"
    if not named:
        return said if gone else f"{said}; its {info['end_seq'] - info['first_seq']} records kept byte for byte"
    lost = ", ".join(lost_seqs(d["first_seq"], d["end_seq"]) for d in named)
    return (f"{said}; every intact record kept byte for byte, the damaged ones still named as damage ({lost}: "
            "`--discard-damaged` drops them)")  # fmt: skip


def _header_entries(info: dict) -> list[dict]:
    """The manifest's damage entries for the segment header (offset 0; a writer that opened
    the segment while it was active sealed it with this entry)."""
    return [d for d in info.get("damaged", ()) if d["offset"] == 0 and d["reason"] == Reason.BAD_SEGMENT_HEADER]


def _unprovable(seg: Segment, info: dict, dropped: set[int], discarded: bool) -> str:
    """Why the header cannot be known from the name, the manifest and the records ("" when
    it can): the file must be the size the manifest states, and every record must be
    intact up to the manifest's end_seq, but for the stretches the manifest names (damaged
    or discarded: at the offsets `dropped`). Its first record, when intact, must state
    the seq its name does (unless `discarded` dropped it); a damaged one, named as damage,
    leaves the name and the manifest, which agree, to state it (a header holds nothing a
    record needs, and the damage keeps its bytes and seqs named)."""
    if seg.size != seg.sealed_size:
        return f"the file is {seg.size} bytes, the manifest says {seg.sealed_size}"
    if seg.size > SEGMENT_HEADER_SIZE and not (discarded and SEGMENT_HEADER_SIZE in dropped):
        first = seg.read_header(SEGMENT_HEADER_SIZE)
        if first is None and SEGMENT_HEADER_SIZE not in dropped:
            return (f"its first record (offset {SEGMENT_HEADER_SIZE}) is damaged too, so no record confirms "
                    f"first_seq {seg.first_seq}")  # fmt: skip
        if first is not None and first.seq != seg.first_seq:
            return (f"its first record states seq {first.seq}, but its name and the manifest say "
                    f"{seg.first_seq}: which is right cannot be told, so nothing is guessed")  # fmt: skip
    result = scan(seg, salvage=bool(dropped))  # records only: a scan never reads the segment header
    bad = [p for p in (*result.damage, *([result.problem] if result.problem else [])) if p.offset not in dropped]
    if bad:
        return (f"a record behind it is damaged too ({bad[0].reason} at offset {bad[0].offset}; "
                "`--discard-damaged` drops it and names its seqs)")  # fmt: skip
    ends_dropped = ends_declared(result, dropped)
    if result.next_seq != info["end_seq"] and not ends_dropped:
        return f"its records end at seq {result.next_seq}, the manifest says {info['end_seq']}"
    return ""


def _new_header(store: Store, seg: Segment) -> bytes:
    """The header again. created_ns and manifest_gen have no value to check them against:
    kept as the damaged header states them (created_ns only times an active segment's age),
    but manifest_gen never later than the manifest's own generation, since a later one
    would make a leftover of this file look like a rolled-back manifest's (recovery)."""
    head = store.fs.pread(seg.fd, SEGMENT_HEADER_SIZE, 0)
    created_ns, gen = SEGMENT_HEADER.unpack_from(head)[4:6] if len(head) == SEGMENT_HEADER_SIZE else (0, 0)
    return pack_segment_header(seg.first_seq, created_ns, min(gen, store.manifest.generation))


def _grow_to_header(store: Store, seg: Segment) -> None:
    """A segment cut into its header (all its records discarded) gets a whole header back,
    so its file grows to the header's size: the manifest states that size first. Were the
    new size committed after the rename, a crash between them would leave a segment larger
    than the manifest says, which nothing may trust; this way a crash leaves it cut short
    again, which the next repair names and discards again."""
    info = next(i for i in store.manifest.segments if i["first_seq"] == seg.first_seq)
    store.commit_manifest(store.manifest.with_damage(seg.first_seq, info.get("damaged", []), info["streams"],
                                                     info.get("aged", {}), size=SEGMENT_HEADER_SIZE))  # fmt: skip
    seg.sealed_size = seg.size = SEGMENT_HEADER_SIZE


def _rewrite(store: Store, seg: Segment, header: bytes) -> None:
    """A copy of the segment with the new header, fsynced, renamed over it, the directory
    fsynced: a crash leaves the old file or the new one (same size, same records, so the
    manifest and the index describe both) and at most a `.tmp`, which a writer removes."""
    store._check_lock()  # as before every commit: LOCK must still be this writer's
    tmp = seg.path + TMP_SUFFIX
    try:
        store.fs.copy_range_atomic(seg.fd, 0, seg.size, seg.path, head=header)
    except OSError:
        try:  # not renamed: the copy may be as large as the segment, on a disk that is full
            if store.fs.exists(tmp):
                store.fs.unlink(tmp)
        except OSError:
            pass  # a leftover `*.tmp`, removed by the writer's next open
        raise
    fd = store.fs.open(seg.path)
    store.fs.close(seg.fd)
    seg.fd = fd


def _forget_header_damage(store: Store, seg: Segment, info: dict) -> None:
    """Drop the header's damage entry: it lost no record, and the header is whole now."""
    entries = _header_entries(info)
    left = [d for d in info.get("damaged", ()) if d not in entries]
    store.commit_manifest(store.manifest.with_damage(seg.first_seq, left, info["streams"], info.get("aged", {})))
    seg.damage = [p for p in seg.damage if not (p.offset == 0 and p.reason == Reason.BAD_SEGMENT_HEADER)]
