"""`fsck --repair`: bring a store back to clean, losing nothing that can be read.

Steps, each safe to repeat after a crash (FORMAT.md, "Repair"): open as the writer (recovery
cuts an unsynced torn tail and names damage below the synced point in the manifest); rebuild
every damaged segment header its name, the manifest and its records prove; rebuild every
index that is missing, damaged or wrong; put every intact record of a side file back into
the store (marked salvaged, never twice) and then move the side file into quarantine; with
`discard_damaged`, forget the named damage and delete the quarantine.
"""

from __future__ import annotations

import json
import os
import types
from dataclasses import dataclass, field

from ..codecs import codec_from_config
from ..errors import CclogError, CorruptionError, StoreLockedError
from .format import (AGED_META_KEY, LOCK, MANIFEST, QUARANTINE, SIDE_FILE, Reason, check_fields, index_size_limit,
                     parse_seq_name, segment_name)
from .fs import FileSystem, FileTooLargeError
from .header_repair import rebuild_headers
from .records import intact_in
from .index import SegmentIndex
from .manifest import Manifest
from .rebuild import rebuild_manifest
from .segment import scan
from .store import Store, describe_damage, open_store
from .window import Window

SALVAGED_META_KEY = "salvaged"


@dataclass
class RepairReport:
    path: str
    actions: list[str] = field(default_factory=list)  # what was changed
    damage_left: list[str] = field(default_factory=list)  # named damage and quarantined files
    # Damage repair would not mend by a guess (a segment header it cannot prove), kept as it
    # is; `--discard-damaged` does not drop it either.
    unproven: list[str] = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        """e2fsck's: 0 clean, 1 repaired, 4 damage left (8, an operational error, is the CLI's)."""
        return 4 if self.damage_left or self.unproven else 1 if self.actions else 0


def repair_store(path: str, *, discard_damaged: bool = False, fs: FileSystem | None = None) -> RepairReport:
    report = RepairReport(path)
    fs = fs or FileSystem()
    _rebuild_manifest_if_damaged(path, fs, report)
    _recreate_missing(path, fs, report, discard_damaged)
    with open_store(path, sync_every_ms=None, sync_every_bytes=None, fs=fs, drop_lost_header=True) as store:
        rec = store.recovery
        report.actions += [f"cut torn tail: {p}" for p in rec.problems]
        # A segment whose header was lost with synced records is sealed with them discarded
        # (recovery), its seqs kept so that no later record takes them.
        lost = {os.path.basename(p.path) for seg in store.sealed for p in seg.discarded}
        for p in rec.damage:
            name = os.path.basename(p.path)
            what = ("removed, its records lost" if name in rec.removed_files else
                    "sealed, its records lost (named as discarded; their seqs are never reused)" if name in lost else
                    "sealed with damage named in the manifest")  # fmt: skip
            report.actions.append(f"{what}: {p}")
        report.actions += [f"removed {n}" for n in rec.removed_files]
        for seg in list(store.sealed):
            if seg.size > seg.sealed_size:
                _quarantine_growth(store, seg, report)
        _declare_sealed_damage(store, report)
        rebuild_headers(store, report.actions, report.unproven)
        _rebuild_indexes(store, report)
        _adopt_quarantine(store, report)
        for name in sorted(n for n in store.fs.listdir(path) if SIDE_FILE.match(n)):
            _salvage(store, name, report)
        if discard_damaged:
            _discard(store, report)
            if report.unproven:  # what contradicted those headers may have been dropped just now
                report.unproven = []
                rebuild_headers(store, report.actions, report.unproven, discarded=True)
        report.damage_left = [describe_damage(d) for d in store.damage()]
        report.damage_left += [f"{QUARANTINE}/{n}: bytes cut from the log" for n in store.manifest.quarantine]
    return report


def _rebuild_manifest_if_damaged(path: str, fs: FileSystem, report: RepairReport) -> None:
    """A MANIFEST that fails its checks, or one that is missing beside segment files (a
    directory without either is no store), is derived again from the segment files."""
    manifest = os.path.join(path, MANIFEST)
    try:
        if not fs.exists(manifest):
            if not fs.exists(path) or not any(n.endswith(".seg") and parse_seq_name(n) for n in fs.listdir(path)):
                return
            raise CorruptionError(f"{manifest} is missing")
        Manifest.load(fs, manifest)
    except CorruptionError:
        # Under the writer's lock, as every other step: a writer still running would commit
        # its own manifest over the rebuilt one.
        lock = fs.lock(os.path.join(path, LOCK))
        if lock is None:
            raise StoreLockedError(f"{path} is locked by another writer; its {MANIFEST} is damaged and "
                                   "is rebuilt only once that writer has stopped") from None  # fmt: skip
        try:
            report.actions += rebuild_manifest(fs, path, codec_from_config("columnar").get_config())
        finally:
            fs.unlock(lock)


def _recreate_missing(path: str, fs: FileSystem, report: RepairReport, discard_damaged: bool) -> None:
    """A segment file the manifest (or the last clean close's checkpoint) says holds records,
    gone: an empty file in its place makes it what the store already repairs, a segment cut
    to nothing, so that its seqs are named lost and never reused. The active segment as
    plain --repair treats one whose header was lost; a sealed one only with
    `discard_damaged` (its records are then dropped for good, and a file restored later
    could no longer take its place)."""
    try:
        manifest = Manifest.load(fs, os.path.join(path, MANIFEST))[0]
    except (CclogError, OSError):
        return  # no store, or one the open refuses with its own words
    wanted = [segment_name(i["first_seq"], i.get("gen", 0)) for i in manifest.segments] if discard_damaged else []
    mark = manifest.checkpoint
    if mark and mark["next_seq"] > mark["first_seq"] >= manifest.end_seq:
        wanted.append(segment_name(mark["first_seq"]))
    missing = [n for n in wanted if not fs.exists(os.path.join(path, n))]
    if not missing:
        return
    lock = fs.lock(os.path.join(path, LOCK))
    if lock is None:
        raise StoreLockedError(f"{path} is locked by another writer; a segment file is missing, and is "
                               "named lost only once that writer has stopped")  # fmt: skip
    try:
        for name in missing:
            fd = fs.open(os.path.join(path, name), write=True, create=True)
            try:
                fs.fsync(fd)
            finally:
                fs.close(fd)
            fs.fsync_dir(path)
            report.actions.append(f"{name} was missing: an empty file put in its place, so that its seqs are "
                                  "named lost (below) and never reused")  # fmt: skip
    finally:
        fs.unlock(lock)


def _rebuild_indexes(store: Store, report: RepairReport) -> None:
    """Write every sealed segment's index again from a scan when it differs from its file."""
    for seg in list(store.sealed):
        path = store.file_path(os.path.basename(store._index_path(seg)))
        try:
            before = store.fs.read_file(path, limit=index_size_limit(seg.size))
        except FileTooLargeError:
            before = b""  # never read: far larger than any index of this segment
        except FileNotFoundError:
            before = None
        seg.set_index(None)
        if before is not None:
            store.fs.unlink(path)
        index = store._sealed_index(seg)  # rebuilt from the segment and written back
        if index.encode(seg.first_seq, seg.size) != before:
            report.actions.append(f"rebuilt index {os.path.basename(path)}")


def _declare_sealed_damage(store: Store, report: RepairReport) -> None:
    """Name in the manifest every damaged stretch of a sealed segment (all of it was
    synced), so that reads know what they miss and the index can be rebuilt around it."""
    for seg, info in zip(store.sealed, store.manifest.segments):
        if seg.size > seg.sealed_size:
            continue  # grown since sealing: left for fsck to report, never guessed at
        result = scan(seg, salvage=True)
        # A segment cut short (recovery) holds its cut as damage the manifest does not name yet.
        declared = {d["offset"] for d in (*info.get("damaged", ()), *info.get("discarded", ()))}
        found = [*result.damage, *([result.problem] if result.problem else [])]
        found += [p for p in seg.damage if seg.cut and p.reason == Reason.SIZE_MISMATCH]
        new = list({p.offset: p for p in found if p.offset not in declared}.values())
        for p in new:
            if p.seqs is None:  # up to the end: the manifest knows where the segment ended
                p.seqs = (result.next_seq, max(info["end_seq"], result.next_seq + 1))
        if new:
            seg.damage = sorted([*{p.offset: p for p in [*seg.damage, *new]}.values()], key=lambda p: p.offset)
            seg.known_damage |= {p.offset for p in new}
            # The lost windows leave the statistics: they are no longer in the store.
            stats = SegmentIndex.build(result.rows).stream_stats()
            damaged = [p.damage_info() for p in seg.damage]
            # The manifest records the cut file's size: the cut is named damage from now on.
            manifest = store.manifest.with_damage(seg.first_seq, damaged, stats, result.aged, size=seg.size)
            store.commit_manifest(manifest)
            seg.cut = False
            report.actions += [f"named damage in a sealed segment in the manifest: {p}" for p in new]


def _quarantine_growth(store: Store, seg, report: RepairReport) -> None:
    """A sealed segment that gained bytes since it was sealed (a bad copy, another program
    appending): they were never records of this store (the manifest states the size it was
    sealed at, all of it synced and indexed), so they are not salvaged into it, but copied
    to `quarantine/NAME.tail-SIZE` (kept until `--discard-damaged`) and cut from the file,
    which is then what was sealed. Order: the copy durable, the cut synced, the manifest
    naming the copy; a crash between leaves the copy (made again, or adopted unnamed)."""
    name = f"{os.path.basename(seg.path)}.tail-{seg.sealed_size}"
    qdir = store.file_path(QUARANTINE)
    store.fs.mkdir(qdir)
    store.fs.fsync_dir(store.path)
    store.fs.copy_range_atomic(seg.fd, seg.sealed_size, seg.size, os.path.join(qdir, name))
    grown = seg.size - seg.sealed_size
    fd = store.fs.open(seg.path, write=True)
    try:
        store.fs.truncate(fd, seg.sealed_size)
        store.fs.fsync(fd)
    finally:
        store.fs.close(fd)
    seg.size = seg.sealed_size
    store.commit_manifest(store.manifest.with_quarantined(name))
    report.actions.append(f"{os.path.basename(seg.path)} had grown by {grown} bytes since it was sealed (at "
                          f"{seg.sealed_size} bytes): they were never part of the store; moved to "
                          f"{QUARANTINE}/{name} and cut from the segment")  # fmt: skip


def _salvage(store: Store, name: str, report: RepairReport) -> None:
    """Put the intact records of side file `name` back (each once), then quarantine it."""
    done = _salvaged_already(store, name)
    put = 0
    fd = store.fs.open(store.file_path(name))  # streamed: a side file may be as large as its tail
    try:
        for offset, header, payload in intact_in(store.fs, fd, 0, store.fs.size(fd)):
            try:
                if check_fields(header) is not None or (header.seq, offset) in done:
                    continue
            except CclogError:
                continue
            window = Window(header.name, header.seq, header.start_ns, header.end_ns, header.count,
                            types.SimpleNamespace(path=store.file_path(name)), offset, header.record_len,
                            (header, payload))  # fmt: skip
            meta = json.loads(header.meta)
            aged = meta.pop(AGED_META_KEY, None)
            mark = {"from": name, "offset": offset, "seq": header.seq}
            meta[SALVAGED_META_KEY] = mark if aged is None else dict(mark, aged=aged)
            store.put_window(header.name, list(window.messages()), meta, codec=json.loads(header.config))
            put += 1
    finally:
        store.fs.close(fd)
    store.sync()
    _quarantine(store, name)
    report.actions.append(f"salvaged {put} intact records of {name} into the store; {name} moved to {QUARANTINE}/")


def _salvaged_already(store: Store, name: str) -> set[tuple[int, int]]:
    """(seq, offset) of the records of `name` a repair put back before (it may have crashed)."""
    done = set()
    for w in store.query(skip_damaged=True):
        mark = w.meta.get(SALVAGED_META_KEY)
        if isinstance(mark, dict) and mark.get("from") == name:
            done.add((mark.get("seq"), mark.get("offset")))
    return done


def _quarantine(store: Store, name: str) -> None:
    qdir = store.file_path(QUARANTINE)
    store.fs.mkdir(qdir)
    store.fs.rename(store.file_path(name), os.path.join(qdir, name))
    store.fs.fsync_dir(qdir)
    store.fs.fsync_dir(store.path)
    store.commit_manifest(store.manifest.with_quarantined(name))


def _adopt_quarantine(store: Store, report: RepairReport) -> None:
    """Files a crashed repair moved into quarantine before naming them in the manifest."""
    qdir = store.file_path(QUARANTINE)
    if store.fs.exists(qdir):
        for name in sorted(set(store.fs.listdir(qdir)) - set(store.manifest.quarantine)):
            store.commit_manifest(store.manifest.with_quarantined(name))
            report.actions.append(f"named {QUARANTINE}/{name} in the manifest")


def _discard(store: Store, report: RepairReport) -> None:
    """Drop named damage and quarantined bytes: asked for explicitly, never by default."""
    gone = [describe_damage(d) for d in store.damage()] + [f"{QUARANTINE}/{n}" for n in store.manifest.quarantine]
    if not gone:
        return
    names = list(store.manifest.quarantine)
    store.commit_manifest(store.manifest.with_damage_discarded())
    for n in names:
        store.fs.unlink(os.path.join(store.file_path(QUARANTINE), n))
    if names:
        store.fs.fsync_dir(store.file_path(QUARANTINE))
    report.actions += [f"discarded {g}" for g in gone]
