"""Opening a store's segments: the sealed ones the manifest names, and the tail after them.

The tail (segments the manifest does not name yet) is scanned and kept to exactly its
valid prefix, as docs/FORMAT.md ("Recovery") specifies; files only an interrupted
compaction or retention step leaves behind are told apart from data and, by the writer,
removed. What was found and done is reported in a `Recovery`.
"""

from __future__ import annotations

import functools
import os
import threading
from operator import itemgetter
from dataclasses import dataclass, field

import xxhash

from ..errors import CorruptionError, DamagedError
from .format import (
    MANIFEST,
    SEGMENT_HEADER_SIZE,
    Reason,
    RecordError,
    index_name,
    parse_seq_name,
    segment_header_fault,
    segment_manifest_gen,
    segment_name,
    unpack_segment_header,
)
from .fs import FileSystem
from . import planted
from .index import OFFSET, SEQ, SegmentIndex
from .manifest import Manifest
from .records import intact_in
from .segment import (Problem, ScanResult, Segment, cut_damage, ends_declared, hash_file, intact_after, lost_seqs,
                      open_segment, scan)


@dataclass
class Recovery:
    """What opening the store found and did."""

    problems: list[Problem] = field(default_factory=list)  # truncated or dropped tails
    # Damage below the synced point found in the tail: kept, declared, never cut.
    damage: list[Problem] = field(default_factory=list)
    skipped: list[Problem] = field(default_factory=list)  # intact records of unknown kind
    sealed_on_open: list[str] = field(default_factory=list)
    removed_files: list[str] = field(default_factory=list)
    # Files of an interrupted compaction or retention step (a generation the manifest does
    # not name, a dropped segment): never data, removed by the writer on open.
    leftovers: list[str] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        return not (self.problems or self.skipped or self.damage)


@dataclass
class _Files:
    """A store directory's segment files, sorted by what the manifest makes of them."""

    named: dict[tuple[int, int], str] = field(default_factory=dict)  # (first_seq, gen) -> name
    tail: dict[int, str] = field(default_factory=dict)  # first_seq -> name, generation 0
    leftovers: list[str] = field(default_factory=list)


def _is_leftover(manifest: Manifest, first_seq: int, gen: int) -> bool:
    """A segment or index file that only an interrupted compaction or retention step
    leaves behind: a generation > 0 the manifest does not name, an older generation of
    a listed segment, or a segment before the store's first (dropped)."""
    sealed_firsts = {info["first_seq"] for info in manifest.segments}
    return gen > 0 or first_seq in sealed_firsts or first_seq < manifest.first_seq


def _dropped_leftover(manifest: Manifest, name: str) -> bool:
    """A generation-0 segment file that only a dropped segment explains (before first_seq)."""
    first_seq, kind, gen = parse_seq_name(name)
    named = {info["first_seq"] for info in manifest.segments}
    return kind == "seg" and gen == 0 and first_seq < manifest.first_seq and first_seq not in named


def _sort_files(names: list[str], manifest: Manifest) -> _Files:
    named = {(info["first_seq"], info.get("gen", 0)) for info in manifest.segments}
    files = _Files()
    for name in names:
        parsed = parse_seq_name(name)
        if parsed is None:
            continue
        first_seq, kind, gen = parsed
        if (first_seq, gen) in named:
            if kind == "seg":
                files.named[first_seq, gen] = name
        elif _is_leftover(manifest, first_seq, gen):
            files.leftovers.append(name)
        elif kind == "seg":
            files.tail[first_seq] = name
    return files


class SegmentOpener:
    """Opens the segments of one manifest version; a writer also repairs the tail."""

    def __init__(self, fs: FileSystem, path: str, readonly: bool, lock: threading.RLock, *,
                 trust_checkpoint: bool = False, drop_lost_header: bool = False):  # fmt: skip
        self.fs, self.path, self.readonly, self.lock = fs, path, readonly, lock
        # A writer drops an active segment whose header is lost although a clean close synced
        # records into it only when asked (repair, which reports them); else it refuses.
        self.drop_lost_header = drop_lost_header
        # A reader may take the part of the active segment a clean close proved durable from
        # the index that close wrote, instead of scanning it (FORMAT.md, "Checkpoint index").
        self.trust_checkpoint = trust_checkpoint
        self.recovery = Recovery()
        self.sealed: list[Segment] = []
        self.tail: list[Segment] = []

    def _file(self, name: str) -> str:
        return os.path.join(self.path, name)

    def open(self, manifest: Manifest) -> None:
        """Fill `sealed` and `tail` (the tail's valid prefix); on failure close what was opened."""
        try:
            files = _sort_files(self.fs.listdir(self.path), manifest)
            self._refuse_rolled_back(manifest, files)
            self._refuse_disagreeing(manifest, files)
            self._open_sealed(manifest, files)
            self._refuse_wrong_end(manifest)
            self._remove_leftovers(files)
            self._refuse_missing_active(manifest, files)
            self._recover_tail(manifest.end_seq, [files.tail[s] for s in sorted(files.tail)], manifest.checkpoint)
        except BaseException:
            for seg in (*self.sealed, *self.tail):
                if seg.fd >= 0:
                    self.fs.close(seg.fd)
                    seg.fd = -1
            raise

    def _refuse_rolled_back(self, manifest: Manifest, files: _Files) -> None:
        """A segment file made under a later manifest generation than this manifest's means
        the manifest was rolled back to an older copy: acting on it (removing what it does not
        name) would delete data. Refuse, touching nothing. A compaction's new generation is
        stamped one ahead of the manifest that was to commit it, so its leftover may be too."""
        later = [(n, 0) for n in files.tail.values()] + [(n, 1) for n in files.leftovers if n.endswith(".seg")]
        for name, ahead in later:
            fd = self.fs.open(self._file(name))
            try:
                gen = segment_manifest_gen(self.fs.pread(fd, SEGMENT_HEADER_SIZE, 0))
            finally:
                self.fs.close(fd)
            if gen > manifest.generation + ahead:
                raise CorruptionError(
                    f"{self.path}: {name} was made under manifest generation {gen}, but {MANIFEST} is "
                    f"generation {manifest.generation}: the manifest was rolled back to an older copy; "
                    "nothing was changed (restore the current MANIFEST)",
                    path=self._file(MANIFEST), reason=Reason.ROLLED_BACK,
                )  # fmt: skip

    def _refuse_disagreeing(self, manifest: Manifest, files: _Files) -> None:
        """A manifest whose CRC holds can still disagree with the files (forged, or written
        by another tool): refuse before acting on it, for what it would make the writer
        delete or readers skip. (Each field's type and range is checked on load.)"""
        first = manifest.first_seq
        dropped = sorted(n for n in files.leftovers if _dropped_leftover(manifest, n))
        starts_at_first = bool(manifest.segments) or first in files.tail
        if dropped and not starts_at_first:
            raise self._disagrees("first_seq", first, f"no segment starts there, yet {dropped[0]} would be "
                                                      "deleted as a segment dropped before it")  # fmt: skip
        for seq, name in sorted(files.tail.items()):
            inside = next((i for i in manifest.segments if i["first_seq"] < seq < i["end_seq"]), None)
            if inside is not None and self._names_itself(name, seq):
                i = manifest.segments.index(inside)
                raise self._disagrees(f"segments[{i}].end_seq", inside["end_seq"], f"{name}, a segment whose "
                                      f"header says it starts at seq {seq}, lies inside it")  # fmt: skip

    def _refuse_wrong_end(self, manifest: Manifest) -> None:
        """The last sealed segment must end where the manifest says: a lower `end_seq` would
        make the active segment (starting at the real end) a sequence gap, which the writer
        deletes; a higher one, with no tail yet, would make it reuse seqs. Only the last can
        be wrong unnoticed (each other's end is the next one's first_seq, which its file
        name and header state). Cost: its index (56 bytes a record) and its last record
        read, or, without a usable index, one scan of that segment."""
        if not self.sealed or self.sealed[-1].size != self.sealed[-1].sealed_size:
            return  # a segment of the wrong size is refused by every read already
        seg = self.sealed[-1]
        # Damage the manifest declares is skipped (salvage), as a read of the segment does:
        # returning early for it let a lower end_seq delete the active segment again.
        declared = seg.known_damage
        index, start = self._last_indexed(seg)
        result = scan(seg, start=start, salvage=bool(declared))
        if _undeclared(result, declared) and start is not None:  # a stale or forged index
            index, result = None, scan(seg, salvage=bool(declared))
        if _undeclared(result, declared) or ends_declared(result, declared):
            return  # other damage is reported by every read; a segment ending in declared damage has no last record to check
        if result.next_seq != seg.next_seq:
            i = len(manifest.segments) - 1
            raise self._disagrees(f"segments[{i}].end_seq", seg.next_seq, f"{os.path.basename(seg.path)} "
                                  f"ends at seq {result.next_seq}")  # fmt: skip
        if index is not None:
            seg.set_index(index)  # read and confirmed: queries need not read it again

    def _last_indexed(self, seg: Segment) -> tuple[SegmentIndex | None, tuple[int, int] | None]:
        """The segment's index and the (offset, seq) of the last record it lists; None, None
        without a usable one."""
        try:
            index = SegmentIndex.read(self.fs, self._file(index_name(seg.first_seq, seg.gen)), seg.first_seq, seg.size)
        except (OSError, RecordError, ValueError, TypeError):
            return None, None
        last = max(index.entries, key=itemgetter(OFFSET), default=None)
        return (None, None) if last is None else (index, (last[OFFSET], last[SEQ]))

    def _names_itself(self, name: str, seq: int) -> bool:
        """Whether the file's segment header is intact and states the seq its name does."""
        fd = self.fs.open(self._file(name))
        try:
            parsed = unpack_segment_header(self.fs.pread(fd, SEGMENT_HEADER_SIZE, 0))
        finally:
            self.fs.close(fd)
        return parsed is not None and parsed[0] == seq

    def _disagrees(self, field: str, value: int, why: str) -> CorruptionError:
        return CorruptionError(f"{self._file(MANIFEST)}: field {field} is {value}, but {why}: the manifest "
                               "does not agree with the segment files; nothing was changed",
                               path=self._file(MANIFEST), reason=Reason.BAD_FIELD)  # fmt: skip

    def _refuse_missing_active(self, manifest: Manifest, files: _Files) -> None:
        """The active segment a clean close proved to hold records must be there: without
        this, a deleted active segment would pass for an empty tail."""
        mark = manifest.checkpoint
        if (mark and mark["next_seq"] > mark["first_seq"] >= manifest.end_seq
                and mark["first_seq"] not in files.tail):  # fmt: skip
            raise CorruptionError(
                f"{self.path}: {segment_name(mark['first_seq'])}, the active segment holding seqs "
                f"{mark['first_seq']}..{mark['next_seq'] - 1} at the last clean close, is missing; restore it, or "
                "`cclog fsck --repair` names those seqs lost (never reused) as for a segment whose header was lost",
                path=self._file(segment_name(mark["first_seq"])), reason=Reason.MISSING_SEGMENT,
            )  # fmt: skip

    def _open_sealed(self, manifest: Manifest, files: _Files) -> None:
        for info in manifest.segments:
            gen = info.get("gen", 0)
            name = files.named.get((info["first_seq"], gen))
            if name is None:
                raise CorruptionError(
                    f"{self.path}: {MANIFEST} lists segment {segment_name(info['first_seq'], gen)}, which is "
                    f"missing ({lost_seqs(info['first_seq'], info['end_seq'])}); restore it, or `cclog fsck --repair "
                    "--discard-damaged` drops those seqs for good (never reused)",
                    path=self._file(MANIFEST), reason=Reason.MISSING_SEGMENT,
                )  # fmt: skip
            seg, _ok = open_segment(self.fs, self._file(name), write=False, lock=self.lock)
            seg.first_seq, seg.next_seq = info["first_seq"], info["end_seq"]
            seg.sealed_size, seg.gen = info["size"], gen
            seg.damage = [Problem(seg.path, d["offset"], d["reason"], "", d["length"],
                                  seqs=(d["first_seq"], d["end_seq"])) for d in info.get("damaged", ())]  # fmt: skip
            seg.known_damage = {d["offset"] for d in (*info.get("damaged", ()), *info.get("discarded", ()))}
            self.sealed.append(seg)
            if seg.size < seg.sealed_size:
                self._open_cut(seg)

    def _open_cut(self, seg: Segment) -> None:
        """A sealed segment cut short since sealing: what it lost is damage below the synced
        point, named as the writer names a torn record there, so that readers get its intact
        records (with --skip-damaged) and not a refusal of the whole store. A writer refuses:
        only `fsck --repair` (which records the cut in the manifest) may go on."""
        cut = cut_damage(seg)
        if not self.readonly and not self.drop_lost_header:  # `open` closes the segments on the way out
            raise DamagedError(f"{self.path}: a writer cannot open the store: {cut}; run `cclog fsck --repair` "
                               "to name what the cut lost in the manifest (its seqs are kept, never reused; "
                               "`--discard-damaged` then drops them)",
                               [cut.damage_info()], path=seg.path, reason=cut.reason)  # fmt: skip
        seg.cut = True
        seg.sealed_size = seg.size  # reads take the file as it is, the cut named as damage
        seg.damage = sorted([*seg.damage, cut], key=lambda p: p.offset)
        seg.known_damage.add(cut.offset)
        if self.readonly:
            self.recovery.damage.append(cut)

    def _remove_leftovers(self, files: _Files) -> None:
        # Only now, with every file the manifest names found, and of the size it states: were
        # one missing or cut short, the other generation might be all that is left of it.
        damaged = {seg.first_seq for seg in self.sealed if seg.size != seg.sealed_size or seg.cut}
        leftovers = [n for n in files.leftovers if parse_seq_name(n)[0] not in damaged]
        self.recovery.leftovers = leftovers
        if leftovers and not self.readonly:
            for name in leftovers:
                self.fs.unlink(self._file(name))
                self.recovery.removed_files.append(name)
            self.fs.fsync_dir(self.path)

    def _recover_tail(self, next_seq: int, names: list[str], checkpoint: dict) -> None:
        """Scan the unsealed segments; keep exactly their valid prefix (see FORMAT.md)."""
        broken = False
        for name in names:
            path = self._file(name)
            first_seq = parse_seq_name(name)[0]
            if first_seq < next_seq:  # older than the manifest's end: not ours to touch
                self.recovery.problems.append(Problem(path, 0, Reason.STRAY_SEGMENT, "ignored"))
                continue
            seg, header_ok = open_segment(self.fs, path, write=not self.readonly, lock=self.lock)
            reason = None
            header_damage = None
            if broken or first_seq != next_seq:
                reason = Reason.DROPPED_SEGMENT if broken else Reason.SEQ_GAP
            elif (not header_ok or seg.first_seq != first_seq) and not _holds_records(seg):
                # Created but its header never reached the disk: it cannot hold synced data.
                reason = Reason.BAD_SEGMENT_HEADER
            elif not header_ok or seg.first_seq != first_seq:
                # The header is fsynced before any record is written: records after a damaged
                # header mean damage to synced data, kept like any other (issue 11, item 6).
                seg.first_seq, seg.next_seq = first_seq, first_seq
                fault = segment_header_fault(self.fs.pread(seg.fd, SEGMENT_HEADER_SIZE, 0)[: seg.size], first_seq)
                header_damage = Problem(path, 0, Reason.BAD_SEGMENT_HEADER, fault, SEGMENT_HEADER_SIZE,
                                        seqs=(first_seq, first_seq))  # fmt: skip
            if reason is Reason.BAD_SEGMENT_HEADER and _vouched(checkpoint, first_seq):
                # A clean close synced records here: they are lost with the header, not torn.
                fault = segment_header_fault(self.fs.pread(seg.fd, SEGMENT_HEADER_SIZE, 0)[: seg.size], first_seq)
                lost = Problem(path, 0, reason, fault, seg.size, seqs=(first_seq, checkpoint["next_seq"]))
                if not self.readonly and not self.drop_lost_header:
                    # Dropping it here (as a torn tail) would lose those records without a word.
                    self.fs.close(seg.fd)
                    raise DamagedError(f"{self.path}: a writer cannot open the store: {lost}; run `cclog fsck "
                                       "--repair` to name what it lost (its seqs are kept, never reused)",
                                       [lost.damage_info()], path=path, reason=reason)  # fmt: skip
                self.recovery.damage.append(lost)
                if not self.readonly:
                    self._keep_lost(seg, lost, checkpoint)
                    broken = True
                    continue
            elif reason is not None:  # not synced: a torn tail
                self.recovery.problems.append(Problem(path, 0, reason, "", seg.size))
            if reason is not None:
                self._drop_segment(seg)
                broken = True
                continue
            broken = self._keep_prefix(seg, checkpoint)
            if header_damage is not None:
                seg.damage.insert(0, header_damage)
                self.recovery.damage.insert(0, header_damage)
            self.tail.append(seg)
            next_seq = seg.next_seq

    def _keep_prefix(self, seg: Segment, checkpoint: dict) -> bool:
        """Scan one tail segment; keep every intact record below the synced point (damage
        there is declared in `seg.damage`, never cut) and cut an unsynced torn tail. True
        when it had to be cut. A reader of a checkpointed segment scans only what followed
        the last clean close, and leaves the records before it to the segment's first use;
        the writer scans only what followed it too, when those bytes still hash the same."""
        deferred = self._defers_prefix(seg, checkpoint)
        verified = None if self.readonly else self._verified_prefix(seg, checkpoint)
        if deferred or verified is not None:
            result = scan(seg, salvage=True, start=(checkpoint["synced"], checkpoint["next_seq"]))
        else:
            result = scan(seg, salvage=True)
        if verified is not None:
            result.rows[:0] = verified[0].rows()
        self.recovery.skipped.extend(result.skipped)
        seg.synced = max(result.synced, SEGMENT_HEADER_SIZE)
        if checkpoint.get("first_seq") == seg.first_seq:
            seg.synced = max(seg.synced, checkpoint["synced"])
        if "torn-tail" in planted.BUGS:
            seg.synced = SEGMENT_HEADER_SIZE
        problems = [*result.damage, *([result.problem] if result.problem else [])]
        ours = checkpoint if checkpoint.get("first_seq") == seg.first_seq else {}
        if ours and result.problem is None and result.end < ours["synced"] and result.next_seq < ours["next_seq"]:
            problems.append(_cut_below_checkpoint(seg, result, ours))
        cut = next((p for p in problems if p.offset >= seg.synced), None)
        seg.damage = [p for p in problems if p.offset < seg.synced]
        _name_lost_seqs(seg.damage, result.next_seq, ours.get("next_seq", 0))
        self.recovery.damage.extend(seg.damage)
        end = cut.offset if cut is not None else seg.size  # the size scanned, never a later one
        seg.rows = [r for r in result.rows if r[5] < end]
        lowest = checkpoint["next_seq"] if deferred or verified is not None else seg.first_seq
        if deferred:
            seg.defer_prefix(functools.partial(self._load_prefix, checkpoint=checkpoint))
        if verified is not None:  # what followed the checkpoint, up to the end kept, is hashed on
            seg.digest = hash_file(self.fs, seg.fd, checkpoint["synced"], end, verified[1])
        seg.next_seq = max([r[2] + 1 for r in seg.rows] + [p.seqs[1] for p in seg.damage] + [lowest])
        if cut is None:
            seg.size = end
            return False
        # A cut is a torn tail, not declared damage: what a salvaging scan found past it is
        # counted below, and the bytes to the end of the snapshot are what is dropped.
        cut.seqs, cut.dropped_bytes = None, seg.size - cut.offset
        # An unfinished put's own parts are no evidence: it was never acknowledged.
        cut.intact_after = intact_after(seg, cut.put_end[0] - 1 if cut.put_end else cut.offset)
        self.recovery.problems.append(cut)
        if not self.readonly:
            if cut.intact_after:
                cut.kept_in = self._keep_tail(seg, cut.offset)
            self.fs.truncate(seg.fd, cut.offset)
            self.fs.fsync(seg.fd)
        seg.size = cut.offset
        return True

    def _defers_prefix(self, seg: Segment, checkpoint: dict) -> bool:
        """Whether a reader may leave the records a clean close proved durable to the
        segment's first use: the checkpoint is this segment's, its synced point lies past the
        segment header and within the file, and the close's index of those bytes is there
        (else it scans now, as before)."""
        return (self.trust_checkpoint and checkpoint.get("first_seq") == seg.first_seq
                and SEGMENT_HEADER_SIZE <= checkpoint["synced"] <= seg.size
                and self.fs.exists(self._file(index_name(seg.first_seq))))  # fmt: skip

    def _verified_prefix(self, seg: Segment, checkpoint: dict) -> tuple[SegmentIndex, xxhash.xxh3_64] | None:
        """Writer: the index a clean close wrote of the segment's first `synced` bytes, and
        the hash of those bytes, when they and the index still hash to the checkpoint's
        `xxh3` (FORMAT.md, "checkpoint"). Any byte changed below the checkpoint since (bit
        rot, a bad copy) or another index makes it None: the writer then scans the segment
        whole and names the damage before it appends. One streamed hash, no record parsed."""
        digest, synced = checkpoint.get("xxh3"), checkpoint.get("synced", 0)
        if digest is None or checkpoint["first_seq"] != seg.first_seq or not SEGMENT_HEADER_SIZE <= synced <= seg.size:
            return None
        data = self._checkpoint_index_bytes(seg)
        if data is None:
            return None
        state = hash_file(self.fs, seg.fd, 0, synced)
        whole = state.copy()
        whole.update(data)
        if whole.intdigest() != digest:
            return None
        index = self._checkpointed_prefix(seg, checkpoint, data)
        return None if index is None else (index, state)

    def _load_prefix(self, seg: Segment, *, checkpoint: dict) -> None:
        """The segment's records below the checkpoint, on its first use (FORMAT.md,
        "Checkpoint index"): from the index the clean close wrote when it describes them
        exactly; else from a scan of the segment, whose damage below the checkpoint is
        declared as an open that scans declares it. Changes nothing until it succeeds."""
        index = self._checkpointed_prefix(seg, checkpoint)
        if index is not None:
            if seg.rows:  # records followed the checkpoint: one index of all of them
                seg.rows[:0] = index.rows()
            else:  # the close's index as it is (a reader's rows are its index's: see Segment)
                seg.set_index(index)
            return
        synced, next_seq = checkpoint["synced"], checkpoint["next_seq"]
        result = scan(seg, salvage=True)  # whole, as an open without a checkpoint does
        problems = [p for p in (*result.damage, *([result.problem] if result.problem else [])) if p.offset < synced]
        rows = [r for r in result.rows if r[5] < synced]
        below = rows[-1][2] + 1 if rows else seg.first_seq
        if not problems and below != next_seq:
            raise CorruptionError(f"{seg.path}: the records below the checkpoint end at seq {below}, but "
                                  f"{MANIFEST}'s checkpoint says {next_seq}; run `cclog fsck`",
                                  path=seg.path, offset=synced, reason=Reason.SEQ_GAP)  # fmt: skip
        _name_lost_seqs(problems, below, next_seq)
        self.recovery.skipped.extend(p for p in result.skipped if p.offset < synced)
        self.recovery.damage.extend(problems)
        seg.damage[:0] = problems
        seg.rows[:0] = rows

    def _checkpointed_prefix(self, seg: Segment, checkpoint: dict, data: bytes | None = None) -> SegmentIndex | None:
        """The index a clean close wrote of the segment's first `checkpoint["synced"]` bytes,
        when it describes exactly those bytes: every seq from the segment's first to the
        checkpoint's `next_seq`, in records that tile the bytes from the segment header to
        the synced point. None otherwise (no index, a damaged or stale one). `data`: the
        index file's bytes, when already read."""
        synced, next_seq = checkpoint["synced"], checkpoint["next_seq"]
        data = self._checkpoint_index_bytes(seg) if data is None else data
        if data is None:
            return None
        try:
            index = SegmentIndex.decode(data, seg.first_seq, synced)
        except (RecordError, ValueError, TypeError):
            return None
        return index if index.tiles(seg.first_seq, next_seq, SEGMENT_HEADER_SIZE, synced) else None

    def _checkpoint_index_bytes(self, seg: Segment) -> bytes | None:
        """The checkpoint index file's bytes; None when it cannot be read."""
        try:
            return self.fs.read_file(self._file(index_name(seg.first_seq)))
        except OSError:
            return None

    def _keep_tail(self, seg: Segment, offset: int) -> str:
        """Copy the bytes recovery is about to cut to a side file, when intact records lie
        among them: they were written but perhaps never synced (a reordered write), or a
        synced record was damaged (bit rot). The log keeps its prefix guarantee either
        way, and no byte is destroyed."""
        name = f"{os.path.basename(seg.path)}.tail-{offset}"
        self.fs.copy_range_atomic(seg.fd, offset, seg.size, self._file(name))  # streamed: any size
        return name

    def _keep_lost(self, seg: Segment, lost: Problem, checkpoint: dict) -> None:
        """Repair's writer: an active segment whose header was lost with the records a clean
        close synced is kept to be sealed (not dropped) with those records in `discarded`, so
        its entry keeps their seqs and the next segment starts after them: dropping it made
        the writer give the lost seqs to new records. Later tail segments are dropped as before."""
        seg.first_seq, seg.next_seq, seg.synced = lost.seqs[0], lost.seqs[1], seg.size
        # Named as a sealed segment cut to its header names its cut: from the header's end
        # over the bytes the close synced (FORMAT.md, "Repair").
        length = max(checkpoint.get("synced", 0), seg.size) - SEGMENT_HEADER_SIZE
        seg.discarded = [Problem(seg.path, SEGMENT_HEADER_SIZE, lost.reason, lost.detail, max(length, 0),
                                 seqs=lost.seqs)]  # fmt: skip
        self.tail.append(seg)

    def _drop_segment(self, seg: Segment) -> None:
        self.fs.close(seg.fd)
        seg.fd = -1
        if not self.readonly:
            self.fs.unlink(seg.path)
            self.fs.fsync_dir(self.path)
            self.recovery.removed_files.append(os.path.basename(seg.path))


def _cut_below_checkpoint(seg: Segment, result: ScanResult, checkpoint: dict) -> Problem:
    """An active segment cut short at a record boundary below the last clean close's synced
    point: its records end cleanly, so no scan problem names what the cut took. Damage below
    the synced point, as a torn record there is; before, the records past the cut were lost
    without a word (fsck clean, cat exit 0) and the writer gave their seqs to new records."""
    return Problem(seg.path, result.end, Reason.TORN,
                   f"the file ends at {seg.size} bytes, the last clean close synced {checkpoint['synced']}",
                   checkpoint["synced"] - result.end, seqs=(result.next_seq, checkpoint["next_seq"]))  # fmt: skip


def _name_lost_seqs(damage: list[Problem], next_seq: int, checkpoint_next: int) -> None:
    """Damage that runs to the end of what was scanned: only the checkpoint knows the seqs
    it lost, from `next_seq` (the scan's) on."""
    for problem in damage:
        if problem.seqs is None:  # an unfinished put's parts run to the end of what was scanned
            lost = problem.put_end[1] if problem.put_end else next_seq + 1
            problem.seqs = (next_seq, max(checkpoint_next, lost))


def _vouched(checkpoint: dict, first_seq: int) -> bool:
    """Whether the last clean close synced records into the segment starting at `first_seq`."""
    return checkpoint.get("first_seq") == first_seq and checkpoint.get("next_seq", first_seq) > first_seq


def _holds_records(seg: Segment) -> bool:
    """Whether any intact record lies past the segment header (within its opened size)."""
    return seg.size > SEGMENT_HEADER_SIZE and next(intact_in(seg.fs, seg.fd, 1, seg.size), None) is not None


def _undeclared(result: ScanResult, declared: set[int]) -> bool:
    """Whether a scan met damage the manifest does not declare."""
    return any(p.offset not in declared for p in (*result.damage, *([result.problem] if result.problem else [])))
