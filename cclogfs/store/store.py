"""The segment store: a flat-namespace append log of compressed, checksummed windows.

See docs/FORMAT.md for the layout and the durability contract this module implements.
"""

from __future__ import annotations

import errno
import heapq
import json
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import xxhash

from .._signals import signals_deferred as _signals_deferred
from ..codecs import codec_from_config
from ..errors import (
    CorruptionError,
    DamagedError,
    InvalidInputError,
    StoreError,
    StoreFailedError,
    StoreIOError,
    StoreLockedError,
)
from . import planted
from .carry import once
from .check import check_stream_name
from .encode import Codecs, Encoded, encode_parts
from .format import (
    AGED_META_KEY,
    LOCK,
    MANIFEST,
    MAX_NS,
    MIN_NS,
    RESERVE,
    SEGMENT_HEADER_SIZE,
    TMP_SUFFIX,
    Reason,
    RecordFlag,
    index_name,
    pack_segment_header,
    parse_seq_name,
    reserve_bytes,
    segment_name,
)
from .fs import FileSystem
from .index import SEQ, START, SegmentIndex, SegmentSpans, merge_stream_stats
from .manifest import Manifest, SealedSegment
from .recovery import Recovery, SegmentOpener
from .segment import WRITE_BUFFER, Segment, hash_file, lost_seqs
from .window import Receipt, Window

if TYPE_CHECKING:
    from .compaction import Dropped, Replacement, RewriteReport

# A reader retries opening this often when a writer's commit lands while it opens (bench
# load: five was too few for a writer sealing every few hundred milliseconds).
OPEN_ATTEMPTS = 20

# Compaction, and what only a writer uses (socket, shutil), are imported when used: a
# reader's start-up is most of a one-second `cclog cat` (issue 14). Its types are exported
# by the package (`cclogfs.store.Replacement`).
__all__ = ["Receipt", "Recovery", "SealedSegment", "Store", "Window", "open_store"]


class Store:
    """A store directory opened by `open_store`. Not for use from several threads at once
    (the group-commit thread is internal and takes the store's lock)."""

    def __init__(self, path: str, fs: FileSystem, readonly: bool, codecs: Codecs,
                 sync_every_ms: float | None, sync_every_bytes: int | None, segment_bytes: int,
                 segment_age_s: float, segment_records: int, verify: bool = False,
                 drop_lost_header: bool = False):  # fmt: skip
        self.path = path
        self.drop_lost_header = drop_lost_header  # see open_store
        self.verify = verify  # a reader scans the whole active segment, checkpoint or not
        self.fs = fs
        self.readonly = readonly
        self.codecs = codecs
        self.sync_every_ms = sync_every_ms
        self.sync_every_bytes = sync_every_bytes
        self.segment_bytes = segment_bytes
        self.segment_age_s = segment_age_s
        self.segment_records = segment_records
        self.recovery = Recovery()
        self.manifest = Manifest({"segments": []})
        self.open_attempts = 0  # manifest reads the last open or refresh took (1 without a retry)
        self.sealed: list[Segment] = []  # in seq order
        self.active: Segment | None = None  # writer: the segment appended to
        self.unsealed: list[Segment] = []  # reader: what it saw past the manifest
        # Package-internal (compaction takes them): the store's lock, and one rewrite or drop
        # at a time, from planning to commit: two overlapping rewrites of a segment would
        # both write its next generation.
        self.lock = threading.RLock()
        self.compaction_lock = threading.Lock()
        self._wake = threading.Condition(self.lock)
        self._lock_fd: int | None = None
        self._failed: BaseException | None = None
        self._closed = False
        self._unsynced_bytes = 0
        self._unsynced_since: float | None = None
        self._flusher: threading.Thread | None = None
        self._sealed_spans: SegmentSpans | None = None
        self._dirty = False  # this writer changed the active segment: close writes a checkpoint

    # -- context manager -------------------------------------------------------------------

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def file_path(self, name: str) -> str:
        """The path of a file of this store."""
        return os.path.join(self.path, name)

    # -- what the manifest says ------------------------------------------------------------

    @property
    def store_id(self) -> str:
        return self.manifest.store_id

    @property
    def format_version(self) -> int:
        return self.manifest.format_version

    @property
    def first_seq(self) -> int:
        """Sequence number of the store's first record (> 0 once retention dropped segments)."""
        return self.manifest.first_seq

    def dropped(self) -> dict[str, Any]:
        """What retention dropped so far: {"segments": n, "streams": {name: stats}} (stats as
        in `streams()`, their time range is what was dropped)."""
        return self.manifest.dropped

    def sealed_segments(self) -> list[SealedSegment]:
        """The sealed segments, in seq order, as the manifest describes them."""
        return list(self.manifest.sealed)

    @property
    def active_first_seq(self) -> int | None:
        """First seq of the writer's active segment; None for a reader."""
        active = self.active
        return active.first_seq if active is not None else None

    def segment_count(self) -> int:
        """Segments sealed, plus the active one (writer) or those past the manifest (reader)."""
        with self.lock:
            return len(self._segments())

    # -- opening ---------------------------------------------------------------------------

    def _open(self, create: bool) -> None:
        manifest_path = self.file_path(MANIFEST)
        if not self.fs.exists(manifest_path):
            self._create_or_finish(create)
        if not self.readonly and self._lock_fd is None:
            self._take_lock()
        self.manifest, _raw = Manifest.load(self.fs, manifest_path)
        if not self.readonly:
            for name in self.fs.listdir(self.path):
                if name.endswith(TMP_SUFFIX):  # a crash while replacing a file
                    self.fs.unlink(self.file_path(name))
                    self.recovery.removed_files.append(name)
        self._open_segments_retrying()
        if not self.readonly:
            self.ensure_reserve()
            self._start_flusher()

    def _create_or_finish(self, create: bool) -> None:
        """A store exists complete or not at all: it is made in a hidden sibling directory
        and renamed into place once its manifest is durable. A directory an older version
        left half made (only LOCK and temporary files) is finished by the next writer."""
        names = self.fs.listdir(self.path) if self.fs.exists(self.path) else []
        if any(n.endswith(".seg") and parse_seq_name(n) for n in names):
            raise StoreError(f"{self.path} holds segment files but no {MANIFEST}: a store whose manifest was lost; "
                             "`cclog fsck --repair` rebuilds it from the segment files")  # fmt: skip
        if any(n != LOCK and not n.endswith(TMP_SUFFIX) for n in names):
            raise StoreError(f"{self.path} holds files but no {MANIFEST} and no segment file: not a cclogfs store")
        half_made = LOCK in names
        if self.readonly or not (create or half_made):
            what = ("its creation was interrupted; open it for writing to finish it" if half_made
                    else "pass create=True to make one")  # fmt: skip
            raise StoreError(f"{self.path} is not a cclogfs store (no {MANIFEST}): {what}")
        manifest = Manifest.new(self.codecs.default.get_config())
        if half_made:
            self._take_lock()
            manifest.commit(self.fs, self.file_path(MANIFEST))
            return
        # A symbolic link (dangling, or to an empty directory) is followed: rename() does not
        # follow it, and failed on it naming the temporary directory ("Not a directory").
        parent, base = os.path.split(os.path.realpath(self.path))
        self.fs.mkdir(parent)  # as before: a store's parent directories are made with it
        _remove_stale_creations(parent, base)
        tmp = os.path.join(parent, f".{base}.creating-{os.getpid()}")
        self.fs.mkdir(tmp)
        try:
            manifest.commit(self.fs, os.path.join(tmp, MANIFEST))
            self.fs.rename(tmp, os.path.join(parent, base))  # the commit point; onto an empty directory too
        except BaseException as err:
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)
            # Another process created the store first: open what it made (a writer of it
            # holding the lock makes this one fail as locked, as with any second writer).
            raced = isinstance(err, OSError) and err.errno in (errno.ENOTEMPTY, errno.EEXIST)
            if raced and self.fs.exists(self.file_path(MANIFEST)):
                return
            raise
        self.fs.fsync_dir(parent)

    def _take_lock(self) -> None:
        path = self.file_path(LOCK)
        fd = self.fs.lock(path)
        if fd is None:
            try:
                holder = self.fs.read_file(path, limit=4096).decode(errors="replace").strip() or "unknown"
            except OSError:
                holder = "unknown"
            raise StoreLockedError(f"{self.path} is locked by another writer ({holder}); "
                                   "open it with readonly=True to read")  # fmt: skip
        self._lock_fd = fd
        # On a full disk the reserve is freed before this writer's first write: opening (the
        # lock's pid, a new active segment, a seal) must work so that retention can run.
        if self._space_short():
            self.release_reserve()
        import socket

        info = json.dumps({"pid": os.getpid(), "host": socket.gethostname()}).encode()
        self.fs.truncate(fd, 0)
        self.fs.pwrite(fd, info, 0)

    def _open_segments_retrying(self) -> None:
        """Load the manifest and open its segments. A reader retries when a listed segment
        is missing: a writer compacted between its reading the manifest and the files."""
        for attempt in range(OPEN_ATTEMPTS):
            self.open_attempts = attempt + 1  # how often this open read the manifest (bench/load.py)
            self.manifest, raw = Manifest.load(self.fs, self.file_path(MANIFEST))
            try:
                self._open_segments(self.recovery.removed_files)
                # A reader must see files and manifest of one moment: if the manifest
                # changed meanwhile, a segment may have been sealed and rewritten under it.
                if not self.readonly or self._still_describes(raw):
                    return
            except (CorruptionError, FileNotFoundError) as err:
                # A reader that read the manifest before a writer's commit sees later files:
                # missing ones, or ones made under a later generation. It reads again.
                retry = isinstance(err, FileNotFoundError) or err.reason in (Reason.MISSING_SEGMENT,
                                                                             Reason.ROLLED_BACK)
                if not (self.readonly and retry and attempt < OPEN_ATTEMPTS - 1):
                    raise
            if attempt == OPEN_ATTEMPTS - 1:
                raise StoreError(f"{self.path}: the store changed under this reader {OPEN_ATTEMPTS} times "
                                 "while it was opening (a writer compacting); try again")  # fmt: skip
            time.sleep(0.002 * attempt)  # a busy writer: give it a moment to finish its step
            self._close_segments()
            self.sealed, self.unsealed, self.recovery = [], [], Recovery()

    def _still_describes(self, raw: bytes) -> bool:
        """Whether the files this reader opened under the manifest `raw` are still one
        moment of the store. A writer that only sealed segments since leaves them so (a
        sealed segment is the same file, whole); one that rewrote or dropped a segment the
        reader took as tail may have deleted its file before the reader listed the directory,
        so that the reader saw the log end early. (A sealed segment of `raw` rewritten or
        dropped is no matter: the reader found it, or it would have failed, and holds it open.)"""
        now, raw_now = Manifest.load(self.fs, self.file_path(MANIFEST))
        if raw_now == raw:
            return True
        end = self.manifest.end_seq
        return (now.store_id == self.manifest.store_id and now.first_seq <= end
                and all(info.get("gen", 0) == 0 for info in now.segments if info["first_seq"] >= end))  # fmt: skip

    def _close_segments(self) -> None:
        for seg in self._segments():
            if seg.fd >= 0:
                self.fs.close(seg.fd)
            seg.fd = -1

    def _open_segments(self, removed: list[str]) -> None:
        # The writer checks the whole active segment: damage below the synced point must be
        # found and sealed before it appends. Below a clean close's checkpoint one hash of the
        # bytes does it, when it matches the checkpoint's; else it scans (FORMAT.md, "checkpoint").
        opener = SegmentOpener(self.fs, self.path, self.readonly, self.lock,
                               trust_checkpoint=self.readonly and not self.verify,
                               drop_lost_header=self.drop_lost_header)  # fmt: skip
        opener.recovery.removed_files = removed
        opener.open(self.manifest)
        self.recovery, self.sealed = opener.recovery, opener.sealed
        if self.readonly:
            self.unsealed = opener.tail
            return
        for seg in opener.tail:
            self._make_durable(seg)
        # The newest tail segment stays active unless it holds damage: that is sealed with
        # the damage named in the manifest, so no later write can hide it.
        last = opener.tail[-1] if opener.tail else None
        keep = len(opener.tail) - 1 if last and not (last.damage or last.discarded) else len(opener.tail)
        for seg in opener.tail[:keep]:  # a crash while sealing left it complete but unsealed
            self._seal(seg)
            self.recovery.sealed_on_open.append(os.path.basename(seg.path))
        tail = opener.tail[keep:]
        self.active = tail[0] if tail else self._new_segment(self.manifest.end_seq)
        if not tail and self.manifest.checkpoint.get("first_seq") == self.active.first_seq:
            # The checkpoint's segment was dropped (a header that never reached the disk):
            # the close states the new one, else the old synced point would read as a cut.
            self._dirty = True

    def _make_durable(self, seg: Segment) -> None:
        """Write again, and fsync, what recovery kept but cannot prove durable: a crash may
        have left it only in the page cache, and after a failed fsync the kernel may have
        marked pages clean that never reached the disk (FORMAT.md, "Durability contract")."""
        if seg.size > seg.synced and "seal-no-fsync" not in planted.BUGS:
            for pos in range(seg.synced, seg.size, WRITE_BUFFER):  # in chunks: memory stays bounded
                self.fs.pwrite(seg.fd, self.fs.pread(seg.fd, min(WRITE_BUFFER, seg.size - pos), pos), pos)
            self.fs.fsync(seg.fd)
            seg.synced = seg.size
            # An older store's records carry no synced length: it stays as it is until written.
            self._dirty = self._dirty or self.manifest.format_version >= 3

    def _index_path(self, seg: Segment) -> str:
        return self.file_path(index_name(seg.first_seq, seg.gen))

    def _new_segment(self, first_seq: int) -> Segment:
        path = self.file_path(segment_name(first_seq))
        created = time.time_ns()
        fd = self.fs.open(path, write=True, create=True)
        header = pack_segment_header(first_seq, created, self.manifest.generation)
        self.fs.pwrite(fd, header, 0)
        self.fs.fsync(fd)
        if "no-dir-fsync" not in planted.BUGS:
            self.fs.fsync_dir(self.path)
        seg = Segment(self.fs, path, first_seq, created, fd, SEGMENT_HEADER_SIZE, lock=self.lock)
        seg.digest = xxhash.xxh3_64(header)  # appends feed it the rest (see _checkpoint)
        return seg

    # -- writing ---------------------------------------------------------------------------

    def check_writable(self) -> None:
        """Raise unless this store may write now (open, not read-only, not failed)."""
        if self._closed:
            raise StoreError(f"{self.path}: the store is closed")
        if self.readonly:
            raise StoreError(f"{self.path} was opened read-only")
        if self._failed is not None:
            raise StoreFailedError(
                f"{self.path}: an earlier write or fsync failed ({self._failed}); the store "
                "refuses further writes because what reached the disk is unknown; reopen it to recover"
            ) from self._failed

    @property
    def failed(self) -> BaseException | None:
        """The write or fsync failure that stopped this writer (None: none)."""
        return self._failed

    def synced_seq(self, *, written: bool = False) -> int | None:
        """The seq of the last record proven durable (an fsync completed past its end), None
        when none is: after a failed write, what reopening the store keeps even after a power
        loss. `written`: the last record handed to the OS instead (fsynced or not), which a
        reopen keeps unless the machine lost power too."""
        with self.lock:
            seg = self.active
            if seg is None:
                return None
            bound = seg.size if written else seg.synced
            for row in reversed(seg.rows):  # (name, count, seq, first, last, offset, length, raw)
                if row[5] + row[6] <= bound:
                    return row[2]
            return seg.first_seq - 1 if seg.first_seq > 0 else None

    def put_window(self, name: str, messages: Sequence[tuple[int, str]],
                   meta: Mapping[str, Any] | None = None, *, codec: Any = None,
                   check_json: bool = True) -> Receipt:  # fmt: skip
        """Store one window of messages (stamp_ns, JSON text) for stream `name`.

        Everything is checked before anything is written: bad input raises
        InvalidInputError and stores nothing. `check_json=False` skips only the JSON parse,
        for texts a parser has just checked (a JSONL or bag source); the text is still
        stored and returned byte for byte. A window over 16 MiB is stored as consecutive
        records of at most 16 MiB each, so that reading one stays cheap (FORMAT.md,
        "Record size and what a read costs"); the receipt says how many.
        """
        if meta is not None and AGED_META_KEY in meta:
            raise InvalidInputError(f"{self.path}: window meta key {AGED_META_KEY!r} is reserved: compaction "
                                    "writes it, with the AGED flag, to say how a window was aged")  # fmt: skip
        parts = encode_parts(self.codecs, name, messages, meta, codec, check_json)
        with self.lock:
            self.check_writable()
            first = self.active.next_seq
            if len(parts) == 1:
                stored = self._append(name, parts[0])
            else:
                stored = self._append_parts(name, parts)
            return Receipt(first, name, parts[0].stamps[0], parts[-1].stamps[-1], sum(len(e.stamps) for e in parts),
                           sum(e.raw_len for e in parts), stored, records=len(parts))  # fmt: skip

    def _append_parts(self, name: str, parts: list[Encoded]) -> int:
        """Append a split window's parts, each but the last flagged PART, as one unit: no
        group commit (and so no seal) falls between them, so a synced point never lies inside
        a window (FORMAT.md, "Splitting"). Whatever stops it half way (an interrupt, an error)
        leaves the store failed: a later put after the unfinished one would make it damage."""
        with _signals_deferred():
            try:
                return sum(self._append(name, enc, last=i == len(parts) - 1) for i, enc in enumerate(parts))
            except BaseException as err:
                self._failed = self._failed or err
                raise

    def _append(self, name: str, enc: Encoded, *, last: bool = True) -> int:
        """Append one record with the next seq (the lock held); its length. `last` False: a
        part of a split window that goes on in the next record (flag PART), after which no
        commit is due yet."""
        seg = self.active
        seq = seg.next_seq
        stamps = enc.stamps
        record = enc.pack(seq, 0 if last else RecordFlag.PART, synced=seg.synced)
        row = (name, len(stamps), seq, stamps[0], stamps[-1], seg.end, len(record), enc.raw_len)
        if self._unsynced_since is None:  # before the append: a commit must never skip its fsync
            self._unsynced_since = time.monotonic()
        if len(seg.pending) + len(record) >= WRITE_BUFFER:  # this append writes the file
            self._check_lock()
        try:
            seg.append(record, row)
        except OSError as err:
            self._failed = err
            raise StoreFailedError(f"{seg.path}: write failed: {err}") from err
        self._unsynced_bytes += len(record)
        self._dirty = True
        # A full segment is committed (and so sealed) at once, not at the next group
        # commit: the limits bound what recovery must scan. Never inside a split window.
        if last and (self._commit_due() or seg.end >= self.segment_bytes or len(seg.rows) >= self.segment_records):
            self._commit()
        return len(record)

    def _commit_due(self) -> bool:
        if self.sync_every_ms is not None and (
            self.sync_every_ms == 0
            or (time.monotonic() - self._unsynced_since) * 1000 >= self.sync_every_ms
        ):
            return True
        return self.sync_every_bytes is not None and self._unsynced_bytes >= self.sync_every_bytes

    def sync(self) -> None:
        """Make every put before this call durable (one fsync for the whole group)."""
        with self.lock:
            self.check_writable()
            self._commit()

    def _check_lock(self) -> None:
        """Refuse to write once LOCK is no longer the file this writer locked: another
        writer may have taken a new one and be writing the same segment (FORMAT.md)."""
        if self._lock_fd is not None and not self.fs.lock_held(self._lock_fd, self.file_path(LOCK)):
            err = StoreFailedError(f"{self.file_path(LOCK)}: the lock file was removed or replaced "
                                   "while this writer held it, so another writer may be writing; "
                                   "nothing more was written (reopen the store)")  # fmt: skip
            self._failed = err
            raise err

    def _commit(self) -> None:
        self._check_lock()
        seg = self.active
        try:
            seg.flush()
            if self._unsynced_since is not None:
                self.fs.fsync(seg.fd)
                seg.synced = seg.size
        except OSError as err:
            self._failed = err
            raise StoreFailedError(f"{seg.path}: fsync failed: {err}; the store refuses further "
                                   "writes (reopen it to recover)") from err  # fmt: skip
        self._unsynced_bytes = 0
        self._unsynced_since = None
        age_s = (time.time_ns() - seg.created_ns) / 1e9
        if (seg.size >= self.segment_bytes or len(seg.rows) >= self.segment_records
                or (seg.rows and age_s >= self.segment_age_s)):  # fmt: skip
            self._roll(seg)

    def _roll(self, seg: Segment) -> None:
        """Seal the active segment and start the next one."""
        try:
            self._seal(seg)
            self.active = self._new_segment(seg.next_seq)
        except OSError as err:
            self._failed = err
            raise StoreFailedError(f"{seg.path}: sealing failed: {err}") from err

    def seal(self) -> bool:
        """Seal the active segment now, if it holds records, so that compaction can rewrite
        them; False when it is empty. Same ordering as automatic sealing (FORMAT.md)."""
        with self.lock:
            self.check_writable()
            sealed = len(self.sealed)
            if "seal-no-fsync" in planted.BUGS:
                self.active.flush()
            else:
                self._commit()  # which seals by itself when a limit is reached
            seg = self.active
            if seg.next_seq == seg.first_seq:
                return len(self.sealed) > sealed
            self._roll(seg)
            return True

    def rewrite(self, fn: Callable[[Window], Replacement | None], *,
                segments: Iterable[int] | None = None) -> RewriteReport:  # fmt: skip
        """Rewrite the records of sealed segments (`segments`: their first_seq; default all).

        `fn(window)` returns None to keep a record byte for byte, or a `Replacement` (same
        stream and seq, times within the old [start_ns, end_ns], at least one message). Every
        rewritten segment becomes a new generation file, all committed by one manifest
        replace: after a crash the store holds either the old or the new records.
        """
        from . import compaction

        return compaction.rewrite(self, fn, segments)

    def drop_oldest(self, carry: Sequence[str] = ()) -> Dropped | None:
        """Retention: remove the oldest sealed segment (never the active one); None when
        there is no sealed segment. The log then starts at the next segment's first seq.
        The windows of the streams `carry` in it are put again first (new seqs), so that
        they outlive it (`cclog record`'s runs: FORMAT.md, "Compaction and retention")."""
        from . import compaction

        return compaction.drop_oldest(self, carry)

    def _seal(self, seg: Segment) -> None:
        """Write the segment's index, then name it in the manifest (it is already synced)."""
        index = seg.index()
        self.fs.write_file_atomic(self._index_path(seg), index.encode(seg.first_seq, seg.size))
        info = {"first_seq": seg.first_seq, "end_seq": seg.next_seq, "size": seg.size,
                "streams": index.stream_stats()}  # fmt: skip
        if seg.damage:
            info["damaged"] = [p.damage_info() for p in seg.damage]
        if seg.discarded:  # records lost with their header (recovery, repair only)
            info["discarded"] = [p.damage_info() for p in seg.discarded]
        self.commit_manifest(self.manifest.with_sealed(info))
        seg.sealed_size = seg.size
        # Named now, as the manifest names it to a store that opens it sealed: `fsck --repair`
        # named the damage of a segment sealed on open a second time.
        seg.known_damage = {p.offset for p in (*seg.damage, *seg.discarded)}
        self.sealed.append(seg)

    def release_reserve(self) -> None:
        """Free the space RESERVE sets aside (package-internal: retention does it right
        before its commit, the writer on open before its first write; FORMAT.md, "Reserve")."""
        path = self.file_path(RESERVE)
        if self.fs.file_size(path) is not None:  # lstat: a symlink is removed as a link
            self.fs.unlink(path)

    def _space_short(self) -> bool:
        """Less free space than the reserve sets aside: the disk is (nearly) full."""
        manifest = self.fs.file_size(self.file_path(MANIFEST)) or 0
        return self.fs.free_bytes(self.path) < reserve_bytes(manifest)

    def ensure_reserve(self) -> bool:
        """Set the reserve's space aside again (package-internal). On a full disk it stays
        short (False) until retention frees space: that space is then free for the next
        drop all the same. Any other failure is the disk's and is raised."""
        path = self.file_path(RESERVE)
        want = reserve_bytes(self.fs.file_size(self.file_path(MANIFEST)) or 0)
        size = self.fs.file_size(path)
        if size is not None and size >= want:
            return True
        try:
            fd = self.fs.open(path, write=True, create=size is None)
            try:
                self.fs.allocate(fd, want)
            finally:
                self.fs.close(fd)
        except StoreIOError as err:
            if err.errno not in (errno.ENOSPC, errno.EDQUOT):
                raise
            return False
        return True

    def commit_manifest(self, manifest: Manifest) -> None:
        """Make `manifest` the store's (package-internal: sealing and compaction); the
        caller holds the lock and updates `sealed` to match."""
        self._check_lock()
        manifest.commit(self.fs, self.file_path(MANIFEST))
        self.manifest = manifest
        self._sealed_spans = None

    def fail(self, err: BaseException) -> None:
        """Refuse further writes: what reached the disk is unknown (package-internal)."""
        self._failed = err

    def _checkpoint(self) -> None:
        """A clean close proves the whole active segment durable (FORMAT.md, "Proof of
        what was synced"), so recovery can tell damage in its last group from a torn tail."""
        seg = self.active
        mark = {"first_seq": seg.first_seq, "synced": seg.synced, "next_seq": seg.next_seq}
        if self._dirty and {k: self.manifest.checkpoint.get(k) for k in mark} != mark:
            try:
                # Its index first, so that a reader need not scan it: a crash before the manifest
                # leaves an index no checkpoint matches, which readers ignore.
                index = seg.index().encode(seg.first_seq, seg.size)
                self.fs.write_file_atomic(self._index_path(seg), index)
                self.commit_manifest(self.manifest.with_checkpoint(**mark, xxh3=self._checkpoint_digest(seg, index)))
            except OSError as err:  # a project error, not a raw OSError from close()
                self._failed = err
                raise StoreFailedError(f"{self.file_path(MANIFEST)}: writing the checkpoint failed: {err}; "
                                       "everything put is synced, reopen the store to recover") from err  # fmt: skip

    def _checkpoint_digest(self, seg: Segment, index: bytes) -> int | None:
        """XXH3-64 of the segment's first `synced` bytes followed by its checkpoint index
        (FORMAT.md, "checkpoint"): from what this writer appended when it knows the bytes
        before them, else read back (after an open that scanned). None when `synced` is not
        the segment's end (a segment rolled to and never written: its header only)."""
        if seg.synced != seg.end:
            return None
        if seg.digest is None:
            seg.digest = hash_file(self.fs, seg.fd, 0, seg.size)
        state = seg.digest.copy()
        state.update(index)
        return state.intdigest()

    def _start_flusher(self) -> None:
        if self.sync_every_ms:
            self._flusher = threading.Thread(target=self._flush_loop, name="cclogfs-group-commit",
                                             daemon=True)  # fmt: skip
            self._flusher.start()

    def _flush_loop(self) -> None:
        """Commit a group once its oldest put is sync_every_ms old, even if no put follows."""
        # Process signals (Ctrl-C, SIGTERM) belong to the main thread: were the kernel to hand
        # one to this thread, a main thread blocked reading its input would not wake up.
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        interval = self.sync_every_ms / 1000
        with self.lock:
            while not self._closed and self._failed is None:
                if self._unsynced_since is None:
                    self._wake.wait(interval)
                    continue
                due = self._unsynced_since + interval - time.monotonic()
                if due > 0:
                    self._wake.wait(due)
                    continue
                try:
                    self._commit()
                except StoreFailedError:
                    return

    def close(self) -> None:
        """Commit what is buffered, seal nothing, release the lock. Idempotent."""
        with self.lock, _signals_deferred():  # a second Ctrl-C must not skip the last fsync
            if self._closed:
                return
            try:
                if not self.readonly and self._failed is None:
                    self._commit()
                    self._checkpoint()
            finally:
                self._closed = True
                self._wake.notify_all()
                self._close_segments()
                if self._lock_fd is not None:
                    self.fs.unlock(self._lock_fd)
                    self._lock_fd = None
        if self._flusher is not None:
            self._flusher.join()

    # -- reading ---------------------------------------------------------------------------

    def _segments(self) -> list[Segment]:
        tail = [self.active] if self.active else self.unsealed
        return [*self.sealed, *tail]

    def _sealed_index(self, seg: Segment) -> SegmentIndex:
        """The sealed segment's index from its .idx file, rebuilt when missing or damaged
        (and written back by an open writer)."""
        return seg.sealed_index(self._index_path(seg), write_back=not self.readonly and not self._closed)

    def segment_first_seqs(self) -> list[int]:
        """First seq of every segment in log order: the sealed ones, then the active one
        (writer) or those past the manifest (reader)."""
        with self.lock:
            return [seg.first_seq for seg in self._segments()]

    def segment_windows(self, first_seq: int) -> list[Window]:
        """Every window of the segment starting at `first_seq`, in its index's order (the
        time index of a sealed segment is rebuilt when missing or damaged, as for a query)."""
        with self.lock:
            found = [seg for seg in self._segments() if seg.first_seq == first_seq]
            if not found:
                raise InvalidInputError(f"{self.path}: no segment starts at seq {first_seq}")
            seg = found[0]
            index = self._sealed_index(seg) if seg in self.sealed else seg.index()
        return [Window(index.names[stream], seq, start, end, count, seg, offset, length)
                for stream, count, seq, start, end, offset, length, _raw_len in index.entries]  # fmt: skip

    def _sealed_candidates(self, name: str, t0: int, t1: int) -> list[Segment]:
        """Sealed segments whose stream `name` may overlap [t0, t1], by binary search."""
        if self._sealed_spans is None:
            self._sealed_spans = SegmentSpans(
                (seg.first_seq, seg, info["streams"]) for seg, info in zip(self.sealed, self.manifest.segments)
            )
        return self._sealed_spans.overlapping(name, t0, t1)

    def streams(self) -> dict[str, dict[str, int]]:
        """Per stream: windows, messages, start_ns, end_ns, raw_bytes, stored_bytes, json_bytes,
        aged (windows flagged AGED)."""
        with self.lock:
            infos = list(self.manifest.segments)
            per_segment = [info["streams"] for info in infos]
            per_segment += [seg.index().stream_stats() for seg in self._segments()[len(self.sealed):]]
        total: dict[str, dict[str, int]] = {}
        for stats in per_segment:
            merge_stream_stats(total, stats)
        for name, t in total.items():  # the messages' own JSON, without the framing's lengths and stamps
            t["json_bytes"] = t["raw_bytes"] - 4 * t["windows"] - 12 * t["messages"]
            t["aged"] = sum(info.get("aged", {}).get(name, 0) for info in infos)
        return dict(sorted(total.items()))

    def damage(self) -> list[dict[str, Any]]:
        """Damage below the synced point that the store knows of and that was not
        discarded: per stretch its `segment` file, `offset`, `length`, the seqs it lost
        [`first_seq`, `end_seq`) and `reason` (FORMAT.md, "Damage")."""
        with self.lock:
            found = [dict(d, segment=segment_name(info["first_seq"], info.get("gen", 0)))
                     for info, d in self.manifest.damage()]  # fmt: skip
            if self.readonly:  # a writer has named the tail's damage in the manifest already
                for seg in self.unsealed:  # what a checkpoint left to first use, loaded now
                    seg.load_prefix()
                found += [dict(p.damage_info(), segment=os.path.basename(p.path)) for p in self.recovery.damage]
        return found

    def _refuse_damaged(self) -> None:
        damage = self.damage()
        if damage:
            where = "; ".join(describe_damage(d) for d in damage)
            raise DamagedError(f"{self.path}: windows lost to damage below the synced point ({where}); a "
                               f"query could miss them, so it refuses: {repair_hint(damage)}, or read the intact "
                               "windows with --skip-damaged", damage, path=self.path,
                               reason=damage[0]["reason"])  # fmt: skip

    def query(self, name: str | None = None, start_ns: int | None = None,
              end_ns: int | None = None, *, skip_damaged: bool = False, copies: bool = False) -> Iterator[Window]:  # fmt: skip
        """Windows of stream `name` (all streams when None) overlapping [start_ns, end_ns],
        in (start_ns, seq) order. Includes this writer's puts not yet synced.

        Raises DamagedError when the store knows of damaged windows (their stream and time
        are lost with them, so any query may miss one), unless `skip_damaged`: then only
        the intact windows come back and `damage()` says what is missing.

        A window retention carried (FORMAT.md, "Carried streams") comes once: the copy a
        crash left beside its original is left out (`carry.once`), unless `copies` (the
        carry asks, so as not to put it a third time)."""
        found = self._query(name, start_ns, end_ns, skip_damaged)
        return found if copies else once(found)

    def _query(self, name: str | None, start_ns: int | None, end_ns: int | None,
               skip_damaged: bool) -> Iterator[Window]:  # fmt: skip
        t0 = MIN_NS if start_ns is None else int(start_ns)
        t1 = MAX_NS if end_ns is None else int(end_ns)
        with self.lock:
            if self._closed:
                raise StoreError(f"{self.path}: the store is closed")
            if not skip_damaged:
                self._refuse_damaged()
            names = [name] if name is not None else list(self.streams())
            runs = []
            for stream in names:
                segs = self._sealed_candidates(stream, t0, t1)
                pairs = [(s, self._sealed_index(s)) for s in segs]
                pairs += [(s, s.index()) for s in self._segments()[len(self.sealed):]]
                for seg, index in pairs:
                    entries = index.streams.get(stream)
                    if entries is not None:
                        hits = entries.overlapping(t0, t1)
                        if hits:
                            runs.append([(e[START], e[SEQ], stream, e, seg) for e in hits])
        for start, seq, stream, e, seg in heapq.merge(*runs, key=lambda r: (r[0], r[1])):
            _id, count, _seq, _start, end, offset, length, _raw_len = e
            yield Window(stream, seq, start, end, count, seg, offset, length)

    def refresh(self) -> None:
        """Reader: see what the writer has committed since this store was opened."""
        if not self.readonly:
            raise StoreError(f"{self.path}: refresh() is for readers; the writer always sees its own puts")
        with self.lock:
            if self._closed:
                raise StoreError(f"{self.path}: the store is closed")
            # Windows already handed out keep their segment objects; once closed here they
            # say so rather than read a generation compaction may have deleted.
            self._close_segments()
            self.sealed, self.unsealed, self._sealed_spans = [], [], None
            self.recovery = Recovery()
            self._open_segments_retrying()

    def data_bytes(self) -> int:
        """Bytes of the store's own files (manifest, segments, indexes): what a storage
        budget counts. Recovery's side files (`.seg.tail-N`) and other strays are left out,
        so evidence kept for a repair never makes retention drop data."""
        names = [n for n in self.fs.listdir(self.path) if n == MANIFEST or parse_seq_name(n) is not None]
        # A file removed meanwhile (a writer compacting while we read) counts 0.
        return sum(self.fs.file_size(self.file_path(name)) or 0 for name in names) + self._close_to_come()

    def _close_to_come(self) -> int:
        """Bytes close() will add: the active segment's index (FORMAT.md, "Checkpoint
        index") and the checkpoint the manifest then names (up to ~100 bytes): counted now, so
        a budget met while recording is met after the close too (it was overshot by the
        size of that index, then by the checkpoint's bytes)."""
        seg = self.active
        if self.readonly or seg is None or not seg.rows:
            return 0
        on_disk = self.fs.file_size(self._index_path(seg)) or 0
        index = max(0, seg.index().encoded_size() - on_disk)
        closed = self.manifest.with_checkpoint(seg.first_seq, seg.size, seg.next_seq, xxh3=(1 << 64) - 1)  # the widest
        manifest = self.fs.file_size(self.file_path(MANIFEST)) or 0
        return index + max(0, closed.encoded_size() - manifest)

    def free_bytes(self) -> int:
        """Bytes still free on the store's file system (for this user)."""
        return self.fs.free_bytes(self.path)

    def disk_bytes(self) -> int:
        """Bytes of every file in the store directory."""
        return sum(self.fs.file_size(self.file_path(name)) or 0 for name in self.fs.listdir(self.path))


def _remove_stale_creations(parent: str, base: str) -> None:
    """Hidden directories of creations of this store whose process is gone (killed)."""
    prefix = f".{base}.creating-"
    for name in os.listdir(parent):
        if name.startswith(prefix) and name[len(prefix):].isdigit():
            try:
                os.kill(int(name[len(prefix):]), 0)
                continue  # still running: another process creating the same store
            except ProcessLookupError:
                import shutil

                shutil.rmtree(os.path.join(parent, name), ignore_errors=True)
            except PermissionError:
                continue


def repair_hint(damage: Sequence[Mapping[str, Any]]) -> str:
    """The repair that ends a read's refusal of `damage`. A damaged segment header (offset
    0) needs only `fsck --repair`: it rebuilds a header whose records are intact, and seals
    a segment whose records were lost with its header with them discarded. Any other
    stretch stays named until `--discard-damaged` (the hint once named it for a header
    too, dropping nothing more than plain --repair but saying the records would go)."""
    if all(d["offset"] == 0 and d["reason"] == Reason.BAD_SEGMENT_HEADER for d in damage):
        return ("run `cclog fsck --repair` (it rebuilds a segment header whose records are intact, or names the "
                "records lost with it, their seqs never reused)")  # fmt: skip
    return "run `cclog fsck --repair --discard-damaged` to drop them (their seqs named)"


def describe_damage(d: Mapping[str, Any]) -> str:
    """One damaged stretch as reports print it."""
    return f"{d['segment']} at offset {d['offset']}, {d['length']} bytes, {lost_seqs(d['first_seq'], d['end_seq'])}: {d['reason']}"


def open_store(path: str | os.PathLike[str], *, create: bool = False, readonly: bool = False,
               codec: Any = "columnar", stream_codecs: Mapping[str, Any] | None = None,
               sync_every_ms: float | None = 200, sync_every_bytes: int | None = 4 << 20,
               segment_bytes: int = 64 << 20, segment_age_s: float = 3600.0,
               segment_records: int = 16384, fs: FileSystem | None = None, verify: bool = False,
               drop_lost_header: bool = False) -> Store:  # fmt: skip
    """Open (or with create=True make) the store at `path`; recovers after a crash.

    codec: default codec (id or config dict) for new records; stream_codecs: per-stream
    overrides. sync_every_ms / sync_every_bytes: the group-commit policy (see FORMAT.md).
    segment_bytes / segment_records / segment_age_s: when the active segment is sealed; they
    bound what recovery has to scan after a crash. verify: a reader checks every record of
    the active segment on open even after a clean close (fsck), instead of taking what the
    close proved durable from its checkpoint index. drop_lost_header: a writer drops an active
    segment whose header is unreadable although the last clean close synced records into it
    (`fsck --repair`, which reports the seqs); without it the writer refuses (DamagedError).
    """
    # the group-commit thread waits up to this long: NaN made it spin, inf overflowed its timer
    if sync_every_ms is not None and not 0 <= sync_every_ms <= threading.TIMEOUT_MAX * 1000:
        raise InvalidInputError(f"sync_every_ms must be from 0 to {threading.TIMEOUT_MAX * 1000:.0f} or None, "
                                f"not {sync_every_ms}")
    if segment_bytes < 4096 or segment_records < 1:
        raise InvalidInputError("segment_bytes must be at least 4096 and segment_records at least 1")
    codecs = Codecs(codec_from_config(codec), {k: codec_from_config(v) for k, v in (stream_codecs or {}).items()})
    store = Store(
        os.fspath(path), fs or FileSystem(), readonly, codecs, sync_every_ms, sync_every_bytes, segment_bytes, segment_age_s, segment_records,
        verify, drop_lost_header,
    )  # fmt: skip
    for name in codecs.per_stream:
        check_stream_name(name)
    try:
        store._open(create)
    except BaseException as err:
        store._closed = True
        store._close_segments()
        if store._lock_fd is not None:
            store.fs.unlock(store._lock_fd)
        if isinstance(err, OSError):  # a path that is a file, unwritable, gone: one line, no traceback
            where = err.filename or store.path
            raise StoreError(f"{store.path}: cannot open the store: {err.strerror or err} ({where})") from err
        raise
    return store

