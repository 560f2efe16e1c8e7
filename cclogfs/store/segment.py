"""One segment file: its append buffer, record reads, and the scan recovery relies on."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import xxhash

from ..errors import CorruptionError
from . import planted
from .format import (
    RECORD_FIXED_SIZE,
    SEGMENT_HEADER_SIZE,
    Reason,
    RecordError,
    RecordFlag,
    RecordHeader,
    check_fields,
    check_fixed,
    parse_header,
    unpack_segment_header,
)
from .fs import FileSystem
from .index import SegmentIndex
from .records import BytesAt, ChunkReader, UnfinishedPut, count_intact_in, intact_in, read_record, records

# Hand buffered records to the OS past this size even when no fsync is due, so the
# writer's memory stays bounded whatever the sync policy.
WRITE_BUFFER = 1 << 20
# Reads of a segment that is only hashed: small enough for malloc to reuse one block (a
# fresh process maps each 4 MiB buffer anew, and its page faults cost more than the hash:
# 40.8 MB took 7.9 ms CPU in 4 MiB reads, 5.0 ms in 256 KiB reads, xxh3 itself 3 ms).
HASH_CHUNK = 256 << 10


def lost_seqs(first: int, end: int) -> str:
    """The seqs [first, end) a damaged stretch lost, in words (a damaged segment header,
    say, loses none: the records after it are whole, though no reader trusts them)."""
    return "no record lost" if end <= first else f"seq {first}" if end == first + 1 else f"seqs {first}..{end - 1}"


@dataclass
class Problem:
    """Something a scan found: where, why, and how many bytes it cost."""

    path: str
    offset: int
    reason: str
    detail: str = ""
    dropped_bytes: int = 0
    intact_after: int = 0  # intact records found past the problem (0 for a plain torn tail)
    kept_in: str = ""  # side file holding the dropped bytes, when intact records were among them
    # Damage below the synced point (never cut): the sequence numbers it lost, [first, end).
    seqs: tuple[int, int] | None = None
    # An unfinished put (`offset` its first part): (offset, seq) one past its last part found.
    put_end: tuple[int, int] | None = None

    def __str__(self) -> str:
        dropped = f", {self.dropped_bytes} bytes dropped" if self.dropped_bytes else ""
        detail = f" ({self.detail})" if self.detail else ""
        intact = f", {self.intact_after} intact records among them" if self.intact_after else ""
        kept = f", kept in {self.kept_in}" if self.kept_in else ""
        if self.seqs is not None:
            lost = lost_seqs(*self.seqs)
            return (f"{self.path} at offset {self.offset}: {self.reason}{detail}: {self.dropped_bytes} bytes "
                    f"below the synced point damaged ({lost})")  # fmt: skip
        return f"{self.path} at offset {self.offset}: {self.reason}{detail}{dropped}{intact}{kept}"

    def damage_info(self) -> dict:
        """The manifest's entry for damage below the synced point (FORMAT.md, "Damage")."""
        first, end = self.seqs
        return {"offset": self.offset, "length": self.dropped_bytes, "first_seq": first, "end_seq": end,
                "reason": self.reason}  # fmt: skip


@dataclass
class ScanResult:
    """The valid prefix of a segment: its index rows, where it ends, what stopped it."""

    rows: list[tuple] = field(default_factory=list)
    end: int = SEGMENT_HEADER_SIZE
    next_seq: int = 0
    problem: Problem | None = None
    skipped: list[Problem] = field(default_factory=list)
    aged: dict[str, int] = field(default_factory=dict)  # per stream: records flagged AGED
    synced: int = 0  # the largest synced length an intact record states
    # With salvage: damaged stretches that intact records follow, each with the seqs it lost.
    damage: list[Problem] = field(default_factory=list)


class Segment:
    """A segment file. Only the active segment is appended to; `pending` holds records
    not yet handed to the OS, and reads serve them from memory."""

    def __init__(self, fs: FileSystem, path: str, first_seq: int, created_ns: int, fd: int,
                 size: int, *, lock: threading.RLock | None = None):  # fmt: skip
        self.fs, self.path, self.first_seq, self.created_ns = fs, path, first_seq, created_ns
        self.lock = lock or threading.RLock()  # the store's: appends, flushes and reads take it
        self.fd = fd
        self.size = size  # bytes handed to the OS
        self.pending = bytearray()
        # Index rows of the records in this segment; a reader's segment opened from a
        # checkpoint holds those below it in its index only (they are never appended to).
        self.rows: list[tuple] = []
        self.next_seq = first_seq
        self.sealed_size = -1  # for a sealed segment: its size in the manifest
        self.cut = False  # a sealed segment found shorter than the manifest says (recovery)
        self.gen = 0  # for a sealed segment: how often compaction rewrote it (names its files)
        self.synced = 0  # bytes proven durable: the size at the last completed fsync
        self.damage: list[Problem] = []  # damage below the synced point (recovery, the manifest)
        self.known_damage: set[int] = set()  # offsets of damage the manifest names or discarded
        # Lost stretches a writer seals straight into `discarded`: records gone with their
        # header (repair), whose seqs the sealed entry keeps so they are never reused.
        self.discarded: list[Problem] = []
        self.index_untrusted = False  # set when a read found a record its index entry misdescribes
        self._index: SegmentIndex | None = None
        self._prefix: Callable[[Segment], None] | None = None  # see defer_prefix
        # Writer: XXH3-64 state of the bytes [0, end), fed as records are appended, so that a
        # clean close states the digest of what it proved durable without reading it back
        # (FORMAT.md, "checkpoint"). None when not known yet (hashed from the file at close).
        self.digest: xxhash.xxh3_64 | None = None

    @property
    def end(self) -> int:
        """Offset one past the last record, buffered ones included."""
        return self.size + len(self.pending)

    def append(self, record: bytes, row: tuple) -> None:
        self.pending += record
        if self.digest is not None:
            self.digest.update(record)
        self.rows.append(row)
        self.next_seq += 1
        self._index = None
        if len(self.pending) >= WRITE_BUFFER:
            self.flush()

    def flush(self) -> None:
        if self.pending:
            self.fs.pwrite(self.fd, bytes(self.pending), self.size)
            self.size += len(self.pending)
            self.pending.clear()

    def read(self, offset: int, length: int) -> bytes:
        """Bytes of this segment as this store sees it: `size` bytes in the file, then (the
        writer's active segment only) its buffer. Nothing past that is read: a reader's view
        is the snapshot it scanned, never a buffer it does not have (FORMAT.md, "One writer")."""
        if offset + length > self.end:
            raise CorruptionError(
                f"{self.path}: record at offset {offset} ({length} bytes) lies past the {self.end} bytes "
                "this store has seen of the segment", path=self.path, offset=offset, reason=Reason.TORN,
            )  # fmt: skip
        if offset >= self.size:
            start = offset - self.size
            return bytes(self.pending[start : start + length])
        return self.fs.pread(self.fd, length, offset)

    def defer_prefix(self, load: Callable[[Segment], None]) -> None:
        """Leave a reader's records below a clean close's checkpoint to `load`, called on
        first use: opening then reads none of them (FORMAT.md, "Checkpoint index")."""
        self._index, self._prefix = None, load

    def load_prefix(self) -> None:
        """Load what `defer_prefix` left for first use; a failure leaves it to the next use."""
        if self._prefix is not None:
            self._prefix(self)
            self._prefix = None

    def index(self) -> SegmentIndex:
        self.load_prefix()
        if self._index is None:
            self._index = SegmentIndex.build(self.rows)
        return self._index

    def distrust_index(self) -> None:
        """A record did not match its index entry: the index (checksum valid, content
        stale or forged) is rebuilt from the segment on next use, and written back."""
        self._index, self.index_untrusted = None, True

    def set_index(self, index: SegmentIndex) -> None:
        """Adopt an index built elsewhere (compaction has one for the generation it wrote)."""
        self._index = index

    def sealed_index(self, index_path: str, *, write_back: bool) -> SegmentIndex:
        """A sealed segment's index from its .idx file at `index_path`, rebuilt by a scan when
        missing or damaged (and then written back when `write_back`)."""
        if self._index is not None:
            return self._index
        if self.size != self.sealed_size:
            # Never answer from a sealed segment that lost or gained bytes: a shorter one
            # would otherwise give a silent hole.
            raise CorruptionError(f"{self.path} is {self.size} bytes but the manifest says it was sealed "
                                  f"at {self.sealed_size}; its records cannot be trusted (`cclog fsck` names why; `cclog fsck --repair` "
                                  "names what a cut lost, or moves bytes added since into quarantine/)",
                                  path=self.path, offset=min(self.size, self.sealed_size),
                                  reason=Reason.SIZE_MISMATCH)  # fmt: skip
        try:
            if self.index_untrusted:
                raise ValueError("a record did not match its index entry")
            self._index = SegmentIndex.read(self.fs, index_path, self.first_seq, self.size)
        except (OSError, RecordError, ValueError, TypeError):
            # Damage the manifest declares is known and skipped; any other is corruption.
            result = scan(self, salvage=bool(self.known_damage))
            declared = self.known_damage
            found = [*result.damage, *([result.problem] if result.problem else [])]
            problem = next((p for p in found if p.offset not in declared), None)
            ends_damaged = ends_declared(result, declared)
            if problem is None and result.next_seq != self.next_seq and not ends_damaged:
                problem = Problem(self.path, result.end, Reason.SEQ_GAP,
                                  f"ends at seq {result.next_seq}, the manifest says {self.next_seq}")  # fmt: skip
            if problem:
                raise CorruptionError(f"{self.path}: cannot rebuild the time index: {problem}",
                                      path=self.path, offset=problem.offset, reason=problem.reason)  # fmt: skip
            self._index = SegmentIndex.build(result.rows)
            if write_back:
                self.fs.write_file_atomic(index_path, self._index.encode(self.first_seq, self.size))
        return self._index

    def read_header(self, offset: int) -> RecordHeader | None:
        """The header of the record at `offset` (its CRC checked, the payload not read), or
        None when it does not frame or check."""
        try:
            header_len = check_fixed(self.read(offset, RECORD_FIXED_SIZE), self.size - offset)
            return parse_header(self.read(offset, header_len))
        except RecordError:
            return None

    def read_record(self, offset: int, length: int) -> tuple[RecordHeader, bytes]:
        """Header and payload of the record at `offset` that the index says is `length`
        bytes long, every check passed."""
        data = self.read(offset, length)
        try:
            header, payload = read_record(BytesAt(data, offset), offset, len(data))
            if header.record_len != length:
                raise RecordError(Reason.INDEX_MISMATCH, f"record is {header.record_len} bytes, index says {length}")
        except RecordError as err:
            raise CorruptionError(
                f"{self.path}: record at offset {offset} is damaged: {err}; `cclog fsck --repair` names it in the "
                "manifest (reads then skip it with --skip-damaged; --discard-damaged drops it)",
                path=self.path, offset=offset, reason=err.reason,
            ) from err  # fmt: skip
        return header, payload


def open_segment(fs: FileSystem, path: str, *, write: bool,
                 lock: threading.RLock | None = None) -> tuple[Segment, bool]:  # fmt: skip
    """Open a segment file; the flag says whether its segment header was intact.

    Its size is taken once, here, and everything that opening does with the file (the scan,
    the count of records past a bad one, the side file) stays within it: a writer may be
    appending, and a second look at the size would see records the scan did not."""
    fd = fs.open(path, write=write)
    size = fs.size(fd)
    parsed = unpack_segment_header(fs.pread(fd, SEGMENT_HEADER_SIZE, 0)[:size])
    first_seq, created_ns = parsed if parsed else (-1, 0)
    return Segment(fs, path, first_seq, created_ns, fd, size, lock=lock), parsed is not None


def hash_file(fs: FileSystem, fd: int, start: int, end: int,
              state: xxhash.xxh3_64 | None = None) -> xxhash.xxh3_64:  # fmt: skip
    """`state` (a new XXH3-64 when None) fed the file's bytes [start, end), in reads of
    HASH_CHUNK: memory stays bounded whatever the segment's size. A file shorter than `end`
    feeds fewer bytes, so its digest differs."""
    state = state or xxhash.xxh3_64()
    for pos in range(start, end, HASH_CHUNK):
        state.update(fs.pread(fd, min(HASH_CHUNK, end - pos), pos))
    return state


def ends_declared(result: ScanResult, declared: set[int]) -> bool:
    """Whether the records stop at damage the manifest names: a torn record, or (for a
    segment cut at a record boundary) the end of the file itself."""
    return (result.problem.offset if result.problem is not None else result.end) in declared


def cut_damage(segment: Segment) -> Problem:
    """What a sealed segment cut short since sealing lost: from its last intact record's
    end to the size it was sealed at, the seqs from the first missing one to its end_seq."""
    result = scan(segment, salvage=bool(segment.known_damage))
    offset = result.problem.offset if result.problem is not None else result.end
    return Problem(segment.path, offset, Reason.SIZE_MISMATCH,
                   f"the file is {segment.size} bytes, it was sealed at {segment.sealed_size}",
                   segment.sealed_size - offset, seqs=(result.next_seq, max(segment.next_seq, result.next_seq)))  # fmt: skip


def scan(segment: Segment, *, salvage: bool = False, start: tuple[int, int] | None = None) -> ScanResult:
    """Read every record from the start (or from `start`: an offset and the seq of the
    record there), checking all of it, up to the first that fails.

    Records of unknown kind or version whose checksums hold are skipped and reported;
    the first record that fails a check ends the valid prefix (recovery truncates there).
    With `salvage`, a failure that intact records of later seqs follow is noted in
    `damage` and the scan goes on from the first of them: only the end stops it.
    """
    fs, fd = segment.fs, segment.fd
    size = segment.size  # the size taken when it was opened: one snapshot (see open_segment)
    pos, seq = start or (SEGMENT_HEADER_SIZE, segment.first_seq)
    result = ScanResult(end=pos, next_seq=seq)
    held: list[tuple] = []  # rows of a split window's parts, kept once its last part is read
    while True:
        try:
            for rec in records(ChunkReader(fs, fd), pos, size, seq):
                _add(result, held, segment.path, rec)
            return result
        except RecordError as err:
            held.clear()  # an unfinished put: its parts are not part of the valid prefix
            if "skip-bad-record" in planted.BUGS:
                found = next_intact(fs, fd, err.offset, size, result.next_seq)
                if found is not None:
                    pos, seq = found
                    continue
            problem = Problem(segment.path, err.offset, err.reason, str(err), size - err.offset)
            result.end = err.offset
            found = _resume(fs, fd, err, size, result.next_seq) if salvage else None
            if found is None:
                if isinstance(err, UnfinishedPut):
                    problem.put_end = err.end
                result.problem = problem
                return result
            pos, seq = found
            problem.dropped_bytes, problem.seqs = pos - err.offset, (result.next_seq, seq)
            result.damage.append(problem)


def _resume(fs: FileSystem, fd: int, err: RecordError, size: int, seq: int) -> tuple[int, int] | None:
    """Where a salvaging scan goes on after `err`: at the record that showed a split window
    unfinished (it is intact), else at the next intact record past the failure."""
    if isinstance(err, UnfinishedPut):
        if err.cause is None:
            return err.end if err.end[0] < size else None
        return next_intact(fs, fd, err.cause.offset, size, seq)
    return next_intact(fs, fd, err.offset, size, seq)


_PART, _AGED = int(RecordFlag.PART), int(RecordFlag.AGED)  # ints: IntFlag arithmetic is slow per record


def _add(result: ScanResult, held: list[tuple], path: str, rec) -> None:
    header = rec.header
    result.synced = max(result.synced, header.synced)
    if rec.skip:
        result.skipped.append(Problem(path, rec.offset, rec.skip, f"kind {header.kind} version "
                                      f"{header.version} flags {header.flags}"))  # fmt: skip
    else:
        row = (header.name, header.count, header.seq, header.start_ns, header.end_ns, rec.offset,
               header.record_len, header.raw_len)  # fmt: skip
        held.append((row, header.flags & _AGED))
        if header.flags & _PART:
            return  # the valid prefix ends before a window until its last part is read
    for row, aged in held:
        result.rows.append(row)
        if aged:
            result.aged[row[0]] = result.aged.get(row[0], 0) + 1
    held.clear()
    result.next_seq, result.end = header.seq + 1, rec.end


def next_intact(fs: FileSystem, fd: int, offset: int, size: int, seq: int) -> tuple[int, int] | None:
    """(offset, seq) of the first intact record past `offset` (and before `size`) whose seq
    is `seq` or later: where a salvaging scan resumes after damage. None when there is none.
    Streamed (`intact_in`): a huge or sparse tail costs no more memory than a small one."""
    for at, header, _payload in intact_in(fs, fd, offset + 1, size):
        try:
            if header.seq >= seq and check_fields(header) is None:
                return at, header.seq
        except RecordError:
            pass
    return None


def intact_after(segment: Segment, offset: int) -> int:
    """How many intact records (every check passed) lie after `offset` and within the
    segment's size: records past the point where a scan stopped. Zero for a torn tail; more
    means damage in the middle, or a later write that landed while an earlier one did not."""
    return count_intact_in(segment.fs, segment.fd, offset + 1, segment.size)
