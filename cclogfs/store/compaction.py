"""Compaction and retention: rewrite sealed segments as a new generation, drop the oldest.

Storage only: what a replacement window holds is the caller's business (upkeep's aging
policy decides that); this module checks that a replacement keeps the record's place in the
log and commits it crash-safely, as docs/FORMAT.md ("Compaction and retention") specifies.

The store passes itself in (`Host` says what this module uses of it); this module does not
import the store, which imports it.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from .._signals import signals_deferred
from ..errors import CorruptionError, InvalidInputError, StoreError, StoreFailedError
from . import planted
from .carry import carry_forward
from .encode import Codecs, encode_window
from .format import (
    AGED_META_KEY,
    KNOWN_FLAGS,
    MANIFEST,
    RECORD_FIXED_SIZE,
    SEGMENT_HEADER_SIZE,
    Reason,
    RecordError,
    RecordFlag,
    RecordHeader,
    check_fixed,
    index_name,
    pack_segment_header,
    parse_header,
    segment_name,
)
from .fs import FileSystem
from .index import SegmentIndex, merge_stream_stats
from .manifest import Manifest, SealedSegment
from .records import ChunkReader, Record, not_continued, records
from .segment import Segment, open_segment
from .window import Window

__all__ = ["Dropped", "Host", "Replacement", "RewriteReport", "drop_oldest", "file_bytes", "rewrite"]


class Host(Protocol):
    """What compaction uses of the store (package-internal API of `Store`)."""

    path: str
    fs: FileSystem
    lock: threading.RLock
    compaction_lock: threading.Lock
    codecs: Codecs
    manifest: Manifest
    sealed: list[Segment]

    def check_writable(self) -> None: ...

    def commit_manifest(self, manifest: Manifest) -> None: ...

    def fail(self, err: BaseException) -> None: ...

    def release_reserve(self) -> None: ...

    def ensure_reserve(self) -> bool: ...

    # retention's carry (carry.py) puts windows again through the public API
    def query(self, name: str | None = None, *, skip_damaged: bool = False) -> Iterator[Window]: ...

    def put_window(self, name: str, messages: Sequence[tuple[int, str]], meta: Mapping[str, Any] | None = None,
                   *, codec: Any = None) -> Any: ...  # fmt: skip

    def sync(self) -> None: ...

    def free_bytes(self) -> int: ...


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
    streams: dict[str, dict[str, int]]  # its stream_stats() (windows, messages, times, bytes), those carried aside
    bytes: int  # segment and index file bytes freed
    carried: list[str] = field(default_factory=list)  # streams whose windows were put again, not lost
    # Its named damage (Store.damage() entries): windows lost there, their streams unknown (a
    # run's record among them, say), are in no stream's statistics: the caller must say them.
    damaged: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class _Plan:
    """A rewritten segment, written and synced but not yet named by the manifest."""

    old_info: dict[str, Any]  # the old generation's manifest entry
    old: Segment
    gen: int
    size: int
    index: SegmentIndex
    info: dict[str, Any]


def _file(store: Host, name: str) -> str:
    return os.path.join(store.path, name)


def _records(seg: Segment, end_seq: int) -> Iterator[tuple[Record, bytes]]:
    """Every record of a sealed segment with its bytes, in log order, each fully checked:
    compaction never copies damage into a new generation."""
    if seg.size != seg.sealed_size:
        raise CorruptionError(f"{seg.path} is {seg.size} bytes but the manifest says it was sealed "
                              f"at {seg.sealed_size}; it cannot be rewritten (run `cclog fsck`)",
                              path=seg.path, offset=min(seg.size, seg.sealed_size),
                              reason=Reason.SIZE_MISMATCH)  # fmt: skip
    source = ChunkReader(seg.fs, seg.fd)
    seq = seg.first_seq
    try:
        for rec in records(source, SEGMENT_HEADER_SIZE, seg.size, seg.first_seq):
            yield rec, source.read(rec.offset, rec.header.record_len)
            seq = rec.header.seq + 1
    except RecordError as err:
        raise CorruptionError(f"{seg.path}: record at offset {err.offset} is damaged: {err}; the segment "
                              "cannot be rewritten (run `cclog fsck`)",
                              path=seg.path, offset=err.offset, reason=err.reason) from err  # fmt: skip
    if seq != end_seq:
        raise CorruptionError(f"{seg.path} ends at seq {seq}, the manifest says {end_seq}",
                              path=seg.path, offset=seg.size, reason=Reason.SEQ_GAP)  # fmt: skip


def _replacement_record(codecs: Codecs, seg: Segment, header: RecordHeader, rep: object) -> bytes:
    """The new record's bytes, every rule checked (raises InvalidInputError)."""
    where = f"{os.path.basename(seg.path)}: replacement for seq {header.seq} of {header.name!r}"
    if not isinstance(rep, Replacement):
        raise InvalidInputError(f"{where}: the rewrite callback returned a {type(rep).__name__}; "
                                "it must return None (keep the record) or a Replacement")  # fmt: skip
    if not isinstance(rep.flags, int) or rep.flags & ~KNOWN_FLAGS:
        raise InvalidInputError(f"{where}: flags {rep.flags!r} hold bits this format does not define")
    if rep.flags & RecordFlag.PART:
        raise InvalidInputError(f"{where}: the PART flag is not the caller's: a replacement keeps the "
                                "PART flag of the record it replaces")  # fmt: skip
    if rep.flags & RecordFlag.AGED and not (isinstance(rep.meta, Mapping) and AGED_META_KEY in rep.meta):
        raise InvalidInputError(f"{where}: the AGED flag needs meta[{AGED_META_KEY!r}] saying how "
                                "the texts differ from what was put")  # fmt: skip
    try:
        enc = encode_window(codecs, header.name, rep.messages, rep.meta, rep.codec, True)
    except InvalidInputError as err:
        raise InvalidInputError(f"{where}: {err}") from err
    first, last = enc.stamps[0], enc.stamps[-1]
    if first < header.start_ns or last > header.end_ns:
        raise InvalidInputError(f"{where}: its messages span {first}..{last} ns, outside the "
                                f"record's {header.start_ns}..{header.end_ns}; a rewrite may not "
                                "move a window in time")  # fmt: skip
    # A part of a split window stays one: the window's records keep their places and flags.
    return enc.pack(header.seq, rep.flags | (header.flags & RecordFlag.PART))


@dataclass
class _Replayed:
    """A segment's records after the callback: the new file's bytes and index rows."""

    buf: bytearray
    rows: list[tuple] = field(default_factory=list)
    aged: dict[str, int] = field(default_factory=dict)
    replaced: int = 0
    kept: int = 0


def _replay(codecs: Codecs, seg: Segment, end_seq: int, fn: Callable, manifest_gen: int) -> _Replayed:
    """Call `fn` on every record of a sealed segment; the records it keeps or replaces.
    `manifest_gen`: the generation the manifest that commits them will have at least."""
    out = _Replayed(bytearray(pack_segment_header(seg.first_seq, seg.created_ns, manifest_gen)))
    last: RecordHeader | None = None  # the record before, when it is a part of a split window
    for rec, data in _records(seg, end_seq):
        header, rep = rec.header, None
        if rec.skip is None:
            rep = fn(Window(header.name, header.seq, header.start_ns, header.end_ns, header.count, seg,
                            rec.offset, header.record_len, record=(header, rec.payload)))  # fmt: skip
        if rep is None:
            record, out.kept = data, out.kept + 1
            new_header = header
        else:
            record, out.replaced = _replacement_record(codecs, seg, header, rep), out.replaced + 1
            new_header = parse_header(record[: check_fixed(record[:RECORD_FIXED_SIZE], len(record))])
        if last is not None and (why := not_continued(last, new_header, rec.skip)):
            raise InvalidInputError(f"{os.path.basename(seg.path)}: replacement for seq {header.seq} of "
                                    f"{header.name!r} would break its split window: {why}; the parts of "
                                    "a window keep its meta (apart from 'aged')")  # fmt: skip
        last = new_header if rec.skip is None and new_header.flags & RecordFlag.PART else None
        if rec.skip is None:
            out.rows.append((new_header.name, new_header.count, new_header.seq, new_header.start_ns,
                             new_header.end_ns, len(out.buf), len(record), new_header.raw_len))  # fmt: skip
            if new_header.flags & RecordFlag.AGED:
                out.aged[new_header.name] = out.aged.get(new_header.name, 0) + 1
        out.buf += record
    return out


def _plan(store: Host, seg: Segment, info: dict[str, Any], fn: Callable, report: RewriteReport) -> _Plan | None:
    """Replay a sealed segment through `fn`; when it replaced any record, write the new
    generation (segment, then index, each durable) and say what the manifest must name."""
    done = _replay(store.codecs, seg, info["end_seq"], fn, store.manifest.generation + 1)
    if not done.replaced:
        return None
    gen, size = seg.gen + 1, len(done.buf)
    index = SegmentIndex.build(done.rows)
    new_info = {"first_seq": seg.first_seq, "end_seq": info["end_seq"], "size": size,
                "streams": index.stream_stats(), "gen": gen}  # fmt: skip
    if done.aged:
        new_info["aged"] = done.aged
    fs = store.fs
    path = _file(store, segment_name(seg.first_seq, gen))
    if fs.exists(path):  # left by an earlier rewrite of this session that failed
        fs.unlink(path)
    # The new generation is complete and durable (data, index, directory entries) before the
    # manifest names it: the manifest rename is the one commit point.
    fd = fs.open(path, write=True, create=True)
    try:
        fs.pwrite(fd, bytes(done.buf), 0)
        fs.fsync(fd)
    finally:
        fs.close(fd)
    fs.fsync_dir(store.path)
    fs.write_file_atomic(_file(store, index_name(seg.first_seq, gen)), index.encode(seg.first_seq, size))
    report.replaced += done.replaced
    report.kept += done.kept
    return _Plan(info, seg, gen, size, index, new_info)


def file_bytes(store: Any, seg: Any, gen: int) -> int:
    """Bytes of one generation of a sealed segment (anything with `first_seq`: a Segment or
    a SealedSegment) of `store` (anything with `path`): its file and its index."""
    fs = getattr(store, "fs", None) or FileSystem()
    names = (segment_name(seg.first_seq, gen), index_name(seg.first_seq, gen))
    return sum(fs.file_size(os.path.join(store.path, name)) or 0 for name in names)


def _remove(store: Host, names: Iterable[str]) -> None:
    for name in names:
        if store.fs.exists(_file(store, name)):
            store.fs.unlink(_file(store, name))
    store.fs.fsync_dir(store.path)


def _partial_files(chosen: Iterable[Segment]) -> list[str]:
    """The next generation's file names of the chosen segments, written or half-written."""
    names = []
    for seg in chosen:
        names += [segment_name(seg.first_seq, seg.gen + 1), index_name(seg.first_seq, seg.gen + 1)]
    return names


def _remove_quietly(store: Host, names: Iterable[str]) -> None:
    """Remove unnamed files after a failed rewrite (never one the manifest names); what
    cannot be removed now is a leftover the writer removes on its next open."""
    with store.lock:
        try:
            _remove(store, sorted(set(names) - store.manifest.named_files()))
        except OSError:
            pass


def _generation_files(plans: list[_Plan], old: bool) -> list[str]:
    """Segment and index file names of the plans' old (or new) generations."""
    names = []
    for p in plans:
        gen = p.old.gen if old else p.gen
        names += [segment_name(p.old.first_seq, gen), index_name(p.old.first_seq, gen)]
    return names


def rewrite(store: Host, fn: Callable[[Window], Replacement | None],
            segments: Iterable[int] | None) -> RewriteReport:  # fmt: skip
    """See `Store.rewrite`. The new generations are planned and written without the store's
    lock (sealed segments never change, so the writer may go on putting meanwhile); the
    lock is held for the commit. Rewrites and drops never overlap."""
    with store.compaction_lock:
        chosen = _choose(store, segments)
        report = RewriteReport()
        plans = _plan_all(store, chosen, fn, report)
        if plans:
            _commit_rewrite(store, plans, report)
        return report


def _choose(store: Host, segments: Iterable[int] | None) -> list[tuple[Segment, dict[str, Any]]]:
    """The sealed segments to rewrite, with their manifest entries."""
    with store.lock:
        store.check_writable()
        infos = {info["first_seq"]: info for info in store.manifest.segments}
        segs = {seg.first_seq: seg for seg in store.sealed}
        wanted = sorted(infos) if segments is None else sorted(set(segments))
        unknown = [s for s in wanted if s not in infos]
        if unknown:
            raise InvalidInputError(f"{store.path}: no sealed segment starts at seq {unknown[0]}; "
                                    f"sealed segments start at {sorted(infos)[:10]}")  # fmt: skip
        return [(segs[s], infos[s]) for s in wanted]


def _plan_all(store: Host, chosen: list[tuple[Segment, dict[str, Any]]], fn: Callable,
              report: RewriteReport) -> list[_Plan]:  # fmt: skip
    """Write the new generations; when any replaced a record, return holding the store's
    lock, every plan checked against the current manifest, ready to commit."""
    plans: list[_Plan] = []
    try:
        for seg, info in chosen:
            plan = _plan(store, seg, info, fn, report)
            if plan is not None:
                plans.append(plan)
        if not plans:
            return plans
        store.lock.acquire()
        try:
            store.check_writable()
            current = {info["first_seq"]: info for info in store.manifest.segments}
            for plan in plans:  # one rewrite or drop at a time; refuse rather than guess
                now = current.get(plan.old.first_seq)
                if now is None or now.get("gen", 0) != plan.old_info.get("gen", 0):
                    raise StoreError(f"{store.path}: segment {os.path.basename(plan.old.path)} was "
                                     "rewritten or dropped while this rewrite ran; nothing committed")  # fmt: skip
        except BaseException:
            store.lock.release()
            raise
    except BaseException as err:
        # Refused, failed (a full disk: both generations must fit) or interrupted before
        # the commit: the manifest still names only the old files, which nothing changed.
        # Remove the unnamed new generations; the store stays usable.
        _remove_quietly(store, _generation_files(plans, old=False) + _partial_files(seg for seg, _ in chosen))
        if isinstance(err, OSError):
            raise StoreError(f"{store.path}: rewriting failed before its commit: {err}; nothing of this "
                             "rewrite was committed: the store is unchanged by it (its new files are "
                             "removed)") from err  # fmt: skip
        raise
    return plans


def _commit_rewrite(store: Host, plans: list[_Plan], report: RewriteReport) -> None:
    """Commit the plans (the caller's `_plan_all` left the store's lock held), then delete
    the old generations."""
    try:  # the lock is held from the check in _plan_all to the end of the commit
        manifest = store.manifest.with_replaced({plan.old.first_seq: plan.info for plan in plans})
        if "early-delete" in planted.BUGS:
            _remove(store, _generation_files(plans, old=True))
        # From the commit on nothing may be undone: once the rename happened, the manifest on
        # disk names the new files, so an interrupt must not reach the cleanup above.
        with signals_deferred():
            try:
                _commit(store, manifest, "rewriting")
            except StoreFailedError:
                raise
            except StoreError:  # nothing committed: the new generations are unnamed
                _remove_quietly(store, _generation_files(plans, old=False))
                raise
            _finish_rewrite(store, plans, report)
    finally:
        store.lock.release()
    # The old generations are no longer named: deleting them needs no lock (the writer's
    # puts need not wait for it), and a crash before it leaves leftovers removed on open.
    with signals_deferred():
        try:
            _remove(store, _generation_files(plans, old=True))
        except OSError as err:
            store.fail(err)
            raise StoreFailedError(f"{store.path}: cleaning up after a rewrite failed: {err}; the "
                                   "rewrite is committed, reopen the store to finish") from err  # fmt: skip


def _commit(store: Host, manifest: Manifest, what: str) -> None:
    """The commit point of a rewrite or drop. A failure before the rename (writing or
    syncing MANIFEST.tmp: a full disk) changed nothing: StoreError, and the store goes on.
    One at the rename's directory fsync, or an exception there, leaves the store failed:
    whether the disk holds the new manifest is unknown, so neither generation is removed."""
    try:
        store.commit_manifest(manifest)
    except StoreFailedError:
        raise
    except OSError as err:
        if not getattr(err, "renamed", False):
            raise StoreError(f"{store.path}: {what} failed before its commit, writing the new manifest: "
                             f"{err}; nothing changed (the manifest names the same segments as before)"
                             ) from err  # fmt: skip
        store.fail(err)
        raise StoreFailedError(f"{store.path}: {what} failed at its commit: the new manifest was renamed "
                               f"into place but {err}, so whether the disk holds it is unknown; the store "
                               "refuses further writes (reopen it: it follows whichever manifest the disk "
                               "holds, and the files of both are kept)") from err  # fmt: skip
    except BaseException as err:
        store.fail(err)
        raise StoreFailedError(f"{store.path}: {what} was interrupted at its commit ({err!r}); the store "
                               "refuses further writes (reopen it: the manifest names either the old or "
                               "the new segments, and both are kept)") from err  # fmt: skip


def _finish_rewrite(store: Host, plans: list[_Plan], report: RewriteReport) -> None:
    """After the commit: swap the new generations in (the old files are deleted after the
    store's lock is released)."""
    with store.lock:
        try:
            for plan in plans:
                old = plan.old
                report.segments.append(old.first_seq)
                report.bytes_before += file_bytes(store, old, old.gen)
                report.bytes_after += file_bytes(store, old, plan.gen)
                merge_stream_stats(report.before, plan.old_info["streams"])
                merge_stream_stats(report.after, plan.info["streams"])
                path = _file(store, segment_name(old.first_seq, plan.gen))
                new, _ok = open_segment(store.fs, path, write=False, lock=store.lock)
                new.first_seq, new.next_seq, new.gen = old.first_seq, old.next_seq, plan.gen
                new.sealed_size = plan.size
                new.set_index(plan.index)
                store.sealed[[s.first_seq for s in store.sealed].index(old.first_seq)] = new
                store.fs.close(old.fd)
                old.fd = -1
        except OSError as err:
            store.fail(err)
            raise StoreFailedError(f"{store.path}: cleaning up after a rewrite failed: {err}; the "
                                   "rewrite is committed, reopen the store to finish"
                                   ) from err  # fmt: skip


def drop_oldest(store: Host, carry: Sequence[str] = ()) -> Dropped | None:
    """See `Store.drop_oldest`."""
    with store.compaction_lock, store.lock:
        store.check_writable()
        if not store.sealed:
            return None
        seg, info = store.sealed[0], store.manifest.segments[0]
        freed = file_bytes(store, seg, seg.gen)
        if "early-delete" in planted.BUGS:
            _remove(store, [segment_name(seg.first_seq, seg.gen), index_name(seg.first_seq, seg.gen)])
        with signals_deferred():  # the carry, the commit and its aftermath run to the end
            # On a full disk the new manifest (and what is carried) fits only in the
            # reserve's space (FORMAT.md, "Reserve").
            manifest_bytes = store.fs.file_size(os.path.join(store.path, MANIFEST)) or 0
            store.release_reserve()
            try:
                kept = carry_forward(store, info, carry, manifest_bytes) if carry else set()
                _commit(store, store.manifest.without_oldest(kept), f"dropping segment {os.path.basename(seg.path)}")
            except StoreFailedError:
                raise
            except StoreError:
                _ensure_reserve_quietly(store)
                raise
            _finish_drop(store, seg)
            _ensure_reserve_quietly(store)
        lost = {name: st for name, st in info["streams"].items() if name not in kept}
        damaged = SealedSegment.from_info(info).damage_dropped()
        return Dropped(info["first_seq"], info["end_seq"], lost, freed, sorted(kept), damaged)


def _ensure_reserve_quietly(store: Host) -> None:
    """Set the reserve aside again; a disk failing now is for the next write to report:
    the drop itself is done (or undone) whatever happens to the reserve."""
    try:
        store.ensure_reserve()
    except OSError:
        pass


def _finish_drop(store: Host, seg: Segment) -> None:
    """After the commit: forget the dropped segment and delete its files."""
    with store.lock:
        try:
            store.sealed.pop(0)
            store.fs.close(seg.fd)
            seg.fd = -1
            # Past the commit point: a crash now leaves only leftovers, removed on open.
            _remove(store, [segment_name(seg.first_seq, seg.gen), index_name(seg.first_seq, seg.gen)])
        except OSError as err:
            store.fail(err)
            raise StoreFailedError(f"{store.path}: cleaning up after dropping segment "
                                   f"{os.path.basename(seg.path)} failed: {err}; the drop is "
                                   "committed, reopen the store to finish") from err  # fmt: skip
