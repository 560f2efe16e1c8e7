"""Compaction and retention: rewrite sealed segments as a new generation, drop the oldest.

Storage only: what a replacement window holds is the caller's business (cclogfs/aging.py
decides that); this module checks that a replacement keeps the record's place in the log
and commits it crash-safely, as docs/FORMAT.md ("Compaction and retention") specifies.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ._signals import signals_deferred
from .errors import CorruptionError, InvalidInputError, StoreError, StoreFailedError
from .format import (
    AGED_META_KEY,
    COMPACTED_FORMAT_VERSION,
    KNOWN_FLAGS,
    MANIFEST,
    RECORD_FIXED_SIZE,
    SEGMENT_HEADER_SIZE,
    Reason,
    RecordError,
    RecordFlag,
    RecordHeader,
    check_fields,
    check_fixed,
    check_payload,
    index_name,
    pack_manifest,
    pack_segment_header,
    parse_header,
    segment_name,
)
from .index import SegmentIndex, merge_stream_stats
from .segment import Segment, open_segment

if TYPE_CHECKING:
    from .store import Store, Window

__all__ = ["Dropped", "Replacement", "RewriteReport", "drop_oldest", "file_bytes", "rewrite"]


@dataclass(frozen=True)
class Replacement:
    """What a rewrite callback returns to replace one record (same stream, same seq)."""

    messages: Sequence[tuple[int, str]]  # (stamp_ns, JSON text), within the old record's times
    meta: Mapping[str, Any]
    codec: Any = None  # codec id or config; None: the store's codec for the stream
    flags: int = 0  # RecordFlag bits; AGED needs meta["aged"] saying how the texts differ


@dataclass
class RewriteReport:
    """What `Store.rewrite` did. Per stream sums cover the rewritten segments only."""

    segments: list[int] = field(default_factory=list)  # first_seq of each rewritten segment
    replaced: int = 0  # records replaced
    kept: int = 0  # records copied verbatim into a rewritten segment
    before: dict[str, dict[str, int]] = field(default_factory=dict)  # stream_stats() sums
    after: dict[str, dict[str, int]] = field(default_factory=dict)
    bytes_before: int = 0  # segment and index file bytes of the rewritten segments
    bytes_after: int = 0


@dataclass(frozen=True)
class Dropped:
    """One segment that retention removed."""

    first_seq: int
    end_seq: int
    streams: dict[str, dict[str, int]]  # its stream_stats(): windows, messages, times, bytes
    bytes: int  # segment and index file bytes freed


@dataclass
class _Plan:
    """A rewritten segment, written and synced but not yet named by the manifest."""

    old_info: dict[str, Any]  # the old generation's manifest entry
    old: Segment
    gen: int
    size: int
    index: SegmentIndex
    info: dict[str, Any]


def _records(seg: Segment, end_seq: int) -> Iterator[tuple[int, RecordHeader, bytes, str | None]]:
    """(offset, header, record bytes, skip reason) of every record of a sealed segment, in
    log order, each fully checked: compaction never copies damage into a new generation."""
    if seg.size != seg.sealed_size:
        raise CorruptionError(f"{seg.path} is {seg.size} bytes but the manifest says it was sealed "
                              f"at {seg.sealed_size}; it cannot be rewritten (run `cclog fsck`)",
                              path=seg.path, offset=min(seg.size, seg.sealed_size),
                              reason=Reason.BAD_LENGTH)  # fmt: skip
    pos, seq = SEGMENT_HEADER_SIZE, seg.first_seq
    while pos < seg.size:
        try:
            header_len = check_fixed(seg.read(pos, RECORD_FIXED_SIZE), seg.size - pos)
            header = parse_header(seg.read(pos, header_len))
            data = seg.read(pos, header.record_len)
            check_payload(header, memoryview(data)[header_len:])
            if header.seq != seq:
                raise RecordError(Reason.SEQ_GAP, f"seq {header.seq}, expected {seq}")
            skip = check_fields(header)
        except RecordError as err:
            raise CorruptionError(f"{seg.path}: record at offset {pos} is damaged: {err}; the segment "
                                  "cannot be rewritten (run `cclog fsck`)",
                                  path=seg.path, offset=pos, reason=err.reason) from err  # fmt: skip
        yield pos, header, data, skip
        pos += header.record_len
        seq += 1
    if seq != end_seq:
        raise CorruptionError(f"{seg.path} ends at seq {seq}, the manifest says {end_seq}",
                              path=seg.path, offset=pos, reason=Reason.SEQ_GAP)  # fmt: skip


def _replacement_record(store: Store, seg: Segment, header: RecordHeader, rep: object) -> bytes:
    """The new record's bytes, every rule checked (raises InvalidInputError)."""
    where = f"{os.path.basename(seg.path)}: replacement for seq {header.seq} of {header.name!r}"
    if not isinstance(rep, Replacement):
        raise InvalidInputError(f"{where}: the rewrite callback returned a {type(rep).__name__}; "
                                "it must return None (keep the record) or a Replacement")  # fmt: skip
    if not isinstance(rep.flags, int) or rep.flags & ~KNOWN_FLAGS:
        raise InvalidInputError(f"{where}: flags {rep.flags!r} hold bits this format does not define")
    if rep.flags & RecordFlag.AGED and not (isinstance(rep.meta, Mapping) and AGED_META_KEY in rep.meta):
        raise InvalidInputError(f"{where}: the AGED flag needs meta[{AGED_META_KEY!r}] saying how "
                                "the texts differ from what was put")  # fmt: skip
    try:
        enc = store._encode_window(header.name, rep.messages, rep.meta, rep.codec, True)
    except InvalidInputError as err:
        raise InvalidInputError(f"{where}: {err}") from err
    first, last = enc.stamps[0], enc.stamps[-1]
    if first < header.start_ns or last > header.end_ns:
        raise InvalidInputError(f"{where}: its messages span {first}..{last} ns, outside the "
                                f"record's {header.start_ns}..{header.end_ns}; a rewrite may not "
                                "move a window in time")  # fmt: skip
    return enc.pack(header.seq, rep.flags)


def _plan(store: Store, seg: Segment, info: dict[str, Any], fn: Callable, report: RewriteReport) -> _Plan | None:
    """Call `fn` on every record of a sealed segment; when it replaced any, write the new
    generation (segment, then index, each durable) and say what the manifest must name."""
    from .store import Window  # here: store imports this module

    buf = bytearray(pack_segment_header(seg.first_seq, seg.created_ns))
    rows, aged, replaced, kept = [], {}, 0, 0
    for offset, header, data, skip in _records(seg, info["end_seq"]):
        rep = None
        if skip is None:
            window = Window(header.name, header.seq, header.start_ns, header.end_ns,
                            header.count, seg, offset, header.record_len)  # fmt: skip
            window._record = (header, data[header.header_len :])  # already read and checked
            rep = fn(window)
        if rep is None:
            record, kept = data, kept + 1
            new_header = header
        else:
            record, replaced = _replacement_record(store, seg, header, rep), replaced + 1
            header_len = check_fixed(record[:RECORD_FIXED_SIZE], len(record))
            new_header = parse_header(record[:header_len])
        if skip is None:
            rows.append((new_header.name, new_header.count, new_header.seq, new_header.start_ns,
                         new_header.end_ns, len(buf), len(record), new_header.raw_len))  # fmt: skip
            if new_header.flags & RecordFlag.AGED:
                aged[new_header.name] = aged.get(new_header.name, 0) + 1
        buf += record
    if not replaced:
        return None
    gen = seg.gen + 1
    index = SegmentIndex.build(rows)
    new_info = {"first_seq": seg.first_seq, "end_seq": info["end_seq"], "size": len(buf),
                "streams": index.stream_stats(), "gen": gen}  # fmt: skip
    if aged:
        new_info["aged"] = aged
    fs = store.fs
    path = store._file(segment_name(seg.first_seq, gen))
    if fs.exists(path):  # left by an earlier rewrite of this session that failed
        fs.unlink(path)
    # The new generation is complete and durable (data, index, directory entries) before the
    # manifest names it: the manifest rename is the one commit point.
    fd = fs.open(path, write=True, create=True)
    try:
        fs.pwrite(fd, bytes(buf), 0)
        fs.fsync(fd)
    finally:
        fs.close(fd)
    fs.fsync_dir(store.path)
    index_path = store._file(index_name(seg.first_seq, gen))
    fs.write_file_atomic(index_path, index.encode(seg.first_seq, len(buf)))
    report.replaced += replaced
    report.kept += kept
    return _Plan(info, seg, gen, len(buf), index, new_info)


def file_bytes(store: Store, seg: Segment, gen: int) -> int:
    """Bytes of one generation of a sealed segment: its file and its index."""
    total = 0
    for name in (segment_name(seg.first_seq, gen), index_name(seg.first_seq, gen)):
        try:
            total += os.path.getsize(store._file(name))
        except FileNotFoundError:
            pass
    return total


def _remove(store: Store, names: Iterable[str]) -> None:
    for name in names:
        if store.fs.exists(store._file(name)):
            store.fs.unlink(store._file(name))
    store.fs.fsync_dir(store.path)


def _partial_files(chosen: Iterable[Segment]) -> list[str]:
    """The next generation's file names of the chosen segments, written or half-written."""
    names = []
    for seg in chosen:
        names += [segment_name(seg.first_seq, seg.gen + 1), index_name(seg.first_seq, seg.gen + 1)]
    return names


def _remove_quietly(store: Store, names: Iterable[str]) -> None:
    """Remove unnamed files after a failed rewrite (never one the manifest names); what
    cannot be removed now is a leftover the writer removes on its next open."""
    with store._lock:
        named = {n for info in store.manifest["segments"]
                 for n in (segment_name(info["first_seq"], info.get("gen", 0)),
                           index_name(info["first_seq"], info.get("gen", 0)))}  # fmt: skip
        try:
            _remove(store, sorted(set(names) - named))
        except OSError:
            pass


def _commit_manifest(store: Store, manifest: dict[str, Any]) -> None:
    store.fs.write_file_atomic(store._file(MANIFEST), pack_manifest(manifest))
    store.manifest = manifest
    store._sealed_by_stream = None


def _generation_files(plans: list[_Plan], old: bool) -> list[str]:
    """Segment and index file names of the plans' old (or new) generations."""
    names = []
    for p in plans:
        gen = p.old.gen if old else p.gen
        names += [segment_name(p.old.first_seq, gen), index_name(p.old.first_seq, gen)]
    return names


def rewrite(store: Store, fn: Callable[[Window], Replacement | None],
            segments: Iterable[int] | None) -> RewriteReport:  # fmt: skip
    """See `Store.rewrite`. The new generations are planned and written without the store's
    lock (sealed segments never change, so the writer may go on putting meanwhile); the
    lock is held for the commit. Rewrites and drops never overlap."""
    with store._compaction_lock:
        return _rewrite(store, fn, segments)


def _rewrite(store: Store, fn: Callable[[Window], Replacement | None],
             segments: Iterable[int] | None) -> RewriteReport:  # fmt: skip
    with store._lock:
        store._check_writable()
        infos = {info["first_seq"]: info for info in store.manifest["segments"]}
        segs = {seg.first_seq: seg for seg in store.sealed}
        wanted = sorted(infos) if segments is None else sorted(set(segments))
        unknown = [s for s in wanted if s not in infos]
        if unknown:
            raise InvalidInputError(f"{store.path}: no sealed segment starts at seq {unknown[0]}; "
                                    f"sealed segments start at {sorted(infos)[:10]}")  # fmt: skip
        chosen = [(segs[s], infos[s]) for s in wanted]
    report = RewriteReport()
    plans: list[_Plan] = []
    try:
        for seg, info in chosen:
            plan = _plan(store, seg, info, fn, report)
            if plan is not None:
                plans.append(plan)
        if not plans:
            return report
        store._lock.acquire()
        try:
            store._check_writable()
            current = {info["first_seq"]: info for info in store.manifest["segments"]}
            for plan in plans:  # one rewrite or drop at a time; refuse rather than guess
                now = current.get(plan.old.first_seq)
                if now is None or now.get("gen", 0) != plan.old_info.get("gen", 0):
                    raise StoreError(f"{store.path}: segment {os.path.basename(plan.old.path)} was "
                                     "rewritten or dropped while this rewrite ran; nothing committed")  # fmt: skip
        except BaseException:
            store._lock.release()
            raise
    except BaseException as err:
        # Refused, failed (a full disk: both generations must fit) or interrupted before
        # the commit: the manifest still names only the old files, which nothing changed.
        # Remove the unnamed new generations; the store stays usable.
        _remove_quietly(store, _generation_files(plans, old=False) + _partial_files(seg for seg, _ in chosen))
        if isinstance(err, OSError):
            raise StoreError(f"{store.path}: rewriting failed before its commit: {err}; the store is "
                             "unchanged") from err  # fmt: skip
        raise
    try:  # the lock is held from the check above to the end of the commit
        by_first = {plan.old.first_seq: plan for plan in plans}
        segs_now = [by_first[i["first_seq"]].info if i["first_seq"] in by_first else i
                    for i in store.manifest["segments"]]  # fmt: skip
        manifest = dict(store.manifest, format_version=COMPACTED_FORMAT_VERSION, segments=segs_now)
        # From the commit on nothing may be undone: once the rename happened, the manifest on
        # disk names the new files, so an interrupt must not reach the cleanup above.
        with signals_deferred():
            _commit(store, manifest, "rewriting")
            _finish_rewrite(store, plans, report)
    finally:
        store._lock.release()
    # The old generations are no longer named: deleting them needs no lock (the writer's
    # puts need not wait for it), and a crash before it leaves leftovers removed on open.
    with signals_deferred():
        try:
            _remove(store, _generation_files(plans, old=True))
        except OSError as err:
            store._failed = err
            raise StoreFailedError(f"{store.path}: cleaning up after a rewrite failed: {err}; the "
                                   "rewrite is committed, reopen the store to finish") from err  # fmt: skip
    return report


def _commit(store: Store, manifest: dict[str, Any], what: str) -> None:
    """The commit point of a rewrite or drop; any failure leaves the store failed (whether
    the rename happened is unknown, so neither generation may be removed)."""
    try:
        _commit_manifest(store, manifest)
    except BaseException as err:
        store._failed = err
        raise StoreFailedError(f"{store.path}: {what} failed at its commit: {err}; the store refuses "
                               "further writes (reopen it: the manifest names either the old or the "
                               "new segments, and both are kept)") from err  # fmt: skip


def _finish_rewrite(store: Store, plans: list[_Plan], report: RewriteReport) -> None:
    """After the commit: swap the new generations in (the old files are deleted after the
    store's lock is released)."""
    with store._lock:
        try:
            for plan in plans:
                old = plan.old
                report.segments.append(old.first_seq)
                report.bytes_before += file_bytes(store, old, old.gen)
                report.bytes_after += file_bytes(store, old, plan.gen)
                merge_stream_stats(report.before, plan.old_info["streams"])
                merge_stream_stats(report.after, plan.info["streams"])
                path = store._file(segment_name(old.first_seq, plan.gen))
                new, _ok = open_segment(store.fs, path, write=False, lock=store._lock)
                new.first_seq, new.next_seq, new.gen = old.first_seq, old.next_seq, plan.gen
                new.sealed_size, new._index = plan.size, plan.index
                store.sealed[[s.first_seq for s in store.sealed].index(old.first_seq)] = new
                store.fs.close(old.fd)
                old.fd = -1
        except OSError as err:
            store._failed = err
            raise StoreFailedError(f"{store.path}: cleaning up after a rewrite failed: {err}; the "
                                   "rewrite is committed, reopen the store to finish"
                                   ) from err  # fmt: skip


def drop_oldest(store: Store) -> Dropped | None:
    """See `Store.drop_oldest`."""
    with store._compaction_lock, store._lock:
        store._check_writable()
        if not store.sealed:
            return None
        seg, info = store.sealed[0], store.manifest["segments"][0]
        before = store.dropped()
        streams = {k: dict(v) for k, v in before["streams"].items()}
        merge_stream_stats(streams, info["streams"])
        dropped = {"segments": before["segments"] + 1, "streams": streams}
        manifest = dict(store.manifest, format_version=COMPACTED_FORMAT_VERSION,
                        first_seq=info["end_seq"], segments=store.manifest["segments"][1:],
                        dropped=dropped)  # fmt: skip
        freed = file_bytes(store, seg, seg.gen)
        with signals_deferred():  # the commit and its aftermath run to the end
            _commit(store, manifest, f"dropping segment {os.path.basename(seg.path)}")
            _finish_drop(store, seg)
        return Dropped(info["first_seq"], info["end_seq"], info["streams"], freed)


def _finish_drop(store: Store, seg: Segment) -> None:
    """After the commit: forget the dropped segment and delete its files."""
    with store._lock:
        try:
            store.sealed.pop(0)
            store.fs.close(seg.fd)
            seg.fd = -1
            # Past the commit point: a crash now leaves only leftovers, removed on open.
            _remove(store, [segment_name(seg.first_seq, seg.gen), index_name(seg.first_seq, seg.gen)])
        except OSError as err:
            store._failed = err
            raise StoreFailedError(f"{store.path}: cleaning up after dropping segment "
                                   f"{os.path.basename(seg.path)} failed: {err}; the drop is "
                                   "committed, reopen the store to finish") from err  # fmt: skip
