"""fsck: check every byte of a store against the format and the manifest, change nothing."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from ..errors import CclogError, UnknownCodecError
from .format import (
    LOCK,
    MANIFEST,
    QUARANTINE,
    RESERVE,
    SEGMENT_HEADER_SIZE,
    SIDE_FILE,
    TMP_SUFFIX,
    Reason,
    RecordError,
    index_name,
    parse_seq_name,
    segment_header_fault,
    segment_name,
    unpack_segment_header,
)
from .records import count_intact_in
from .fs import FileSystem
from .index import SegmentIndex
from .manifest import SealedSegment
from .segment import Problem, Segment, ends_declared, scan
from .store import Store, describe_damage, open_store


@dataclass
class Finding:
    severity: str  # "error": data is damaged or missing; "warning": recovery will mend it
    where: str
    what: str

    def __str__(self) -> str:
        return f"{self.severity}: {self.where}: {self.what}"


@dataclass
class FsckReport:
    path: str
    segments: int = 0
    records: int = 0
    messages: int = 0
    decoded: int = 0
    aged: int = 0  # windows flagged AGED (texts within the error bounds their meta states)
    findings: list[Finding] = field(default_factory=list)

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "error"]

    def add(self, severity: str, where: str, what: str) -> None:
        self.findings.append(Finding(severity, where, what))


def check_store(path: str, *, deep: bool = False, fs: FileSystem | None = None) -> FsckReport:
    """Scan every segment fully (sealed ones too), verify sequence continuity, the manifest's
    statistics and the indexes; with `deep`, decode every window's messages as well."""
    fs = fs or FileSystem()
    report = FsckReport(path)
    try:
        store = open_store(path, readonly=True, fs=fs, verify=True)
    except CclogError as err:
        report.add("error", path, str(err))
        return report
    with store:
        for p in store.recovery.problems:
            if p.intact_after:  # not a plain torn tail: synced records may be among them
                report.add("error", _loc(p), f"{p.reason} in the active segment with {p.intact_after} intact "
                                             f"records after it; the writer will keep the {p.dropped_bytes} "
                                             "bytes from here in a side file and truncate")  # fmt: skip
            elif p.reason == Reason.UNFINISHED_PUT:  # a crash (or a writer now) between the parts of a put
                report.add("warning", _loc(p), f"{p.detail}: a put never acknowledged; the writer will cut "
                                               f"its {p.dropped_bytes} bytes on open, readers do not show it")  # fmt: skip
            else:
                report.add("warning", _loc(p), f"{p.reason}: the writer will truncate this torn tail on open "
                                               f"({p.dropped_bytes} bytes of unsynced writes)")  # fmt: skip
        for d in store.damage():
            report.add("error", f"{d['segment']}@{d['offset']}",
                       f"damage below the synced point, kept and not cut: {describe_damage(d)}")  # fmt: skip
        for name in store.manifest.quarantine:
            report.add("error", f"{QUARANTINE}/{name}", "bytes cut from the log, kept in quarantine until "
                                                       "`cclog fsck --repair --discard-damaged`")  # fmt: skip
        for p in store.recovery.skipped:
            report.add("warning", _loc(p), f"{p.reason} (intact; written by a newer cclogfs?), skipped")
        for name in store.recovery.leftovers:
            report.add("warning", name, "left by an interrupted compaction or retention step (not named by "
                                        "the manifest); the writer removes it on open")  # fmt: skip
        leftovers = set(store.recovery.leftovers)
        _check_sealed(store, fs, report)
        _check_checkpoint_index(store, fs, report)
        firsts = store.segment_first_seqs()
        report.segments = len(firsts)
        for first_seq in firsts[len(store.sealed_segments()):]:
            windows = store.segment_windows(first_seq)
            report.records += len(windows)
            report.messages += sum(w.count for w in windows)
        if deep:
            _decode_all(store, report)
    _check_names(path, fs, leftovers, report)
    return report


def _check_names(path: str, fs: FileSystem, leftovers: set[str], report: FsckReport) -> None:
    """Every file in the directory is one the store may hold; side files are evidence."""
    names = set(fs.listdir(path))
    for name in sorted(names):
        parsed = parse_seq_name(name)
        if (parsed and parsed[1] == "idx" and name not in leftovers
                and segment_name(parsed[0], parsed[2]) not in names):  # fmt: skip
            report.add("warning", name, "index of a segment that does not exist")
        elif SIDE_FILE.match(name):
            intact = _count_side_file(fs, os.path.join(path, name))
            if intact:
                report.add("error", name, f"bytes recovery cut from the log hold {intact} intact records "
                                          "(perhaps acknowledged): they are not in the store")  # fmt: skip
            else:
                report.add("warning", name, "bytes recovery cut from the log (no intact record among them)")
        elif not parsed and name not in (MANIFEST, LOCK, RESERVE, QUARANTINE) and not name.endswith(TMP_SUFFIX):
            report.add("warning", name, "not a file a cclogfs store holds")



def _count_side_file(fs: FileSystem, path: str) -> int:
    """Intact records in a side file, streamed: it may be as large as the tail it was cut from."""
    fd = fs.open(path)
    try:
        return count_intact_in(fs, fd, 0, fs.size(fd))
    finally:
        fs.close(fd)


def _decode_all(store: Store, report: FsckReport) -> None:
    """Decode every window, segment by segment, so one damaged segment hides no other."""
    for first_seq in store.segment_first_seqs():
        try:
            windows = store.segment_windows(first_seq)
        except CclogError as err:
            report.add("error", _segment_file(store, first_seq), f"windows cannot be listed for --deep: {err}")
            continue
        for window in windows:
            where = f"{os.path.basename(window.segment_path)}@{window.offset}"
            try:
                window.meta  # noqa: B018 - a JSON object, like the codec config messages() checks
                for _ in window.messages():
                    pass
                report.decoded += 1
            except UnknownCodecError as err:  # intact, written by a newer cclogfs: not damage
                report.add("warning", where, f"window seq {window.seq}: {err}")
            except CclogError as err:
                report.add("error", where, f"window seq {window.seq} of {window.name!r} does not decode: {err}")


def _segment_file(store: Store, first_seq: int) -> str:
    """The file name of the segment starting at `first_seq` (its current generation)."""
    gens = {s.first_seq: s.gen for s in store.sealed_segments()}
    return segment_name(first_seq, gens.get(first_seq, 0))


def _loc(p: Problem) -> str:
    return f"{os.path.basename(p.path)}@{p.offset}"


def _check_sealed(store: Store, fs: FileSystem, report: FsckReport) -> None:
    expect_seq = store.first_seq
    sealed = store.sealed_segments()
    for info, opened in zip(sealed, store.sealed):
        path = opened.path
        checked, header_ok = _as_found(fs, opened)
        if not header_ok or checked.first_seq != info.first_seq:
            report.add("error", os.path.basename(path), _header_damage(fs, opened, info))
            # The manifest and the file name agree on where its records start: they are
            # checked as any other (the header holds nothing a record needs).
            checked.first_seq = info.first_seq
        if info.first_seq != expect_seq:
            report.add("error", os.path.basename(path),
                       f"starts at seq {info.first_seq}, expected {expect_seq}: a gap")  # fmt: skip
        _check_segment(store, fs, info, checked, report)
        expect_seq = info.end_seq
    tail = store.segment_first_seqs()[len(sealed):]
    if tail and tail[0] != expect_seq:
        report.add("error", segment_name(tail[0]), f"starts at seq {tail[0]}, expected {expect_seq}: a gap")


def _header_damage(fs: FileSystem, opened: Segment, info: SealedSegment) -> str:
    """A sealed segment's damaged header, and what the manifest says the segment holds."""
    fault = segment_header_fault(fs.pread(opened.fd, SEGMENT_HEADER_SIZE, 0)[: opened.size], info.first_seq)
    starts = [s["start_ns"] for s in info.streams.values() if s.get("windows")]
    ends = [s["end_ns"] for s in info.streams.values() if s.get("windows")]
    span = f", {min(starts)}..{max(ends)} ns" if starts and ends else ""
    held = f"seqs {info.first_seq}..{info.end_seq - 1}" if info.end_seq > info.first_seq else "no record"
    return (f"segment header (offset 0, {SEGMENT_HEADER_SIZE} bytes) is damaged: {fault}; the manifest says "
            f"the segment holds {held}{span} ({info.size} bytes); `cclog fsck --repair` rebuilds the header "
            "from its name and the manifest when its first record, if intact, agrees on first_seq")  # fmt: skip


def _as_found(fs: FileSystem, opened: Segment) -> tuple[Segment, bool]:
    """The sealed segment as the store opened it, with its header as the file states it.
    Its open file, not its name: a writer may drop or rewrite it while fsck runs (the open
    file still reads), and reopening by name then failed with a raw FileNotFoundError."""
    parsed = unpack_segment_header(fs.pread(opened.fd, SEGMENT_HEADER_SIZE, 0)[: opened.size])
    first_seq, created_ns = parsed if parsed else (-1, 0)
    return Segment(fs, opened.path, first_seq, created_ns, opened.fd, opened.size), parsed is not None


def _check_segment(store: Store, fs: FileSystem, info: SealedSegment, checked: Segment, report: FsckReport) -> None:
    """Scan one sealed segment and hold it against its manifest entry and its index."""
    name = os.path.basename(checked.path)
    known = _known_damage(store, info.first_seq)  # reported once, from the manifest
    result = scan(checked, salvage=bool(known))
    for p in result.skipped:
        report.add("warning", _loc(p), f"{p.reason}, skipped")
    found = [*result.damage, *([result.problem] if result.problem else [])]
    unknown = [p for p in found if p.offset not in known]
    # Bytes added past the sealed size (a bad copy, another program appending): not damage of
    # a record, and repair has a way with them.
    grown = checked.size > info.size and result.end >= info.size and all(p.offset >= info.size for p in unknown)
    if grown:
        report.add("error", name, f"is {checked.size} bytes, it was sealed at {info.size}: "
                                  f"{checked.size - info.size} bytes were added since; `cclog fsck --repair` "
                                  f"moves them to {QUARANTINE}/ and cuts the file back")  # fmt: skip
        unknown = []
    elif unknown:
        p = unknown[0]
        report.add("error", _loc(p), f"{p.reason} in a sealed segment")
        _check_past_damage(store, fs, info, checked, p.offset, report)
    elif result.end != info.size and not found or checked.size != info.size:
        report.add("error", name, f"is {checked.size} bytes, the manifest says {info.size}")
    ends_known = ends_declared(result, known)
    if not unknown and not ends_known and result.next_seq != info.end_seq:
        report.add("error", name, f"ends at seq {result.next_seq}, the manifest says {info.end_seq}")
    report.records += len(result.rows)
    report.messages += sum(r[1] for r in result.rows)
    if not unknown:
        scanned = SegmentIndex.build(result.rows)
        if scanned.stream_stats() != info.streams:
            report.add("error", name, "stream statistics differ from the manifest's")
        if result.aged != info.aged:
            report.add("error", name, f"aged windows per stream {result.aged} differ from the "
                                      f"manifest's {info.aged}")  # fmt: skip
        report.aged += sum(result.aged.values())
        if not grown:  # its index describes the sealed size, which repair cuts the file back to
            _check_index(store, fs, info, checked, scanned, report)


def _known_damage(store: Store, first_seq: int) -> set[int]:
    """Offsets of the damage the manifest names for a sealed segment, or that was discarded."""
    for info in store.manifest.segments:
        if info["first_seq"] == first_seq:
            return {d["offset"] for d in (*info.get("damaged", ()), *info.get("discarded", ()))}
    return set()


def _index_path(store: Store, info: SealedSegment) -> str:
    return store.file_path(index_name(info.first_seq, info.gen))


def _check_past_damage(store: Store, fs: FileSystem, info: SealedSegment, seg: Segment, offset: int,
                       report: FsckReport) -> None:  # fmt: skip
    """The scan cannot frame records past damage, but the index can: check each one."""
    try:
        index = SegmentIndex.read(fs, _index_path(store, info), seg.first_seq, seg.size)
    except Exception:  # noqa: BLE001 - no usable index: nothing more can be framed
        report.add("error", os.path.basename(seg.path), f"no usable index: records after offset {offset} "
                                                       "cannot be framed")  # fmt: skip
        return
    bad = good = 0
    for _stream, count, _seq, _start, _end, at, length, _raw_len in index.entries:
        if at <= offset:
            continue
        try:
            seg.read_record(at, length)
            good += 1
            report.records += 1
            report.messages += count
        except CclogError as err:
            bad += 1
            report.add("error", f"{os.path.basename(seg.path)}@{at}", str(err))
    report.add("warning", os.path.basename(seg.path), f"{good} records after the damage are intact and "
                                                      f"readable through the index, {bad} are not")  # fmt: skip


def _check_checkpoint_index(store: Store, fs: FileSystem, report: FsckReport) -> None:
    """The index a clean close wrote of the active segment (FORMAT.md, "Checkpoint index"),
    held against the scan of the bytes it describes."""
    mark = store.manifest.checkpoint
    tail = [seg for seg in store.unsealed if seg.first_seq == mark.get("first_seq")]
    if not tail:
        return
    where = index_name(mark["first_seq"])
    try:
        stored = SegmentIndex.decode(fs.read_file(store.file_path(where)), mark["first_seq"], mark["synced"])
    except FileNotFoundError:  # older versions wrote none: readers scan
        return
    except RecordError as err:
        if err.reason != Reason.INDEX_MISMATCH:
            report.add("warning", where, f"damaged ({err}); readers scan the active segment instead, and the "
                                         "writer writes it again at its next clean close")  # fmt: skip
        return  # of another size than the checkpoint: a close cut short, which readers ignore
    scanned = SegmentIndex.build(r for r in tail[0].rows if r[5] < mark["synced"])
    if stored.rows() != scanned.rows():
        report.add("warning", where, "does not match the active segment; reads through it refuse the records "
                                     "it misdescribes, and the writer writes it again at its next clean close")  # fmt: skip


def _check_index(store: Store, fs: FileSystem, info: SealedSegment, seg: Segment, scanned: SegmentIndex,
                 report: FsckReport) -> None:  # fmt: skip
    path = _index_path(store, info)
    where = os.path.basename(path)
    try:
        stored = SegmentIndex.read(fs, path, seg.first_seq, seg.size)
    except FileNotFoundError:
        report.add("warning", where, "missing; the writer rebuilds it from the segment on first use")
        return
    except Exception as err:  # noqa: BLE001 - any failure to parse is the same finding
        report.add("warning", where, f"damaged ({err}); the writer rebuilds it from the segment")
        return
    if stored.names != scanned.names or stored.entries != scanned.entries:
        report.add("warning", where, "does not match the segment; the writer rebuilds it")


__all__ = ["Finding", "FsckReport", "check_store"]
