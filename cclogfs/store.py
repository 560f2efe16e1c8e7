"""The segment store: a flat-namespace append log of compressed, checksummed windows.

See docs/FORMAT.md for the layout and the durability contract this module implements.
"""

from __future__ import annotations

import heapq
import json
import os
import signal
import socket
import threading
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import compaction
from ._signals import signals_deferred as _signals_deferred
from .compaction import Dropped, Replacement, RewriteReport
from .codecs import Codec, codec_from_config, codec_numeric_id, raw_size
from .errors import (
    CorruptionError,
    InvalidInputError,
    StoreError,
    StoreFailedError,
    StoreLockedError,
)
from .format import (
    AGED_META_KEY,
    FORMAT_VERSION,
    FORMAT_VERSIONS,
    LOCK,
    MANIFEST,
    MAX_CONFIG,
    MAX_META,
    MAX_NS,
    MIN_NS,
    MAX_RAW,
    SEGMENT_HEADER_SIZE,
    TMP_SUFFIX,
    Reason,
    RecordError,
    RecordFlag,
    index_name,
    pack_manifest,
    pack_record,
    pack_segment_header,
    parse_seq_name,
    segment_name,
    unpack_manifest,
)
from .fs import FileSystem
from .index import SegmentIndex, merge_stream_stats, overlap_slice
from .segment import Problem, Segment, intact_after, open_segment, scan
from .validate import check_stream_name, encode_messages

__all__ = ["Dropped", "Receipt", "Recovery", "Replacement", "RewriteReport", "SealedSegment", "Store", "Window",
           "open_store"]  # fmt: skip


@dataclass(frozen=True)
class Receipt:
    """What `put_window` stored. Durable once a later `sync()` (or group commit) completes."""

    seq: int
    name: str
    start_ns: int
    end_ns: int
    count: int
    raw_bytes: int
    stored_bytes: int


@dataclass(frozen=True)
class SealedSegment:
    """A sealed segment as the manifest names it: what upkeep and fsck may know of it."""

    first_seq: int
    end_seq: int
    size: int  # bytes of the segment file
    gen: int  # rewrite generation (0 until compaction rewrites it)
    streams: dict[str, dict[str, int]]  # per-stream statistics, as `streams()` sums them
    aged: dict[str, int]  # per stream: windows flagged AGED


@dataclass
class Recovery:
    """What opening the store found and did."""

    problems: list[Problem] = field(default_factory=list)  # truncated or dropped tails
    skipped: list[Problem] = field(default_factory=list)  # intact records of unknown kind
    sealed_on_open: list[str] = field(default_factory=list)
    removed_files: list[str] = field(default_factory=list)
    # Files of an interrupted compaction or retention step (a generation the manifest does
    # not name, a dropped segment): never data, removed by the writer on open.
    leftovers: list[str] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        return not (self.problems or self.skipped)


class Window:
    """One stored window, as a query returns it. Reads its record on first use."""

    __slots__ = ("name", "seq", "start_ns", "end_ns", "count", "_segment", "_offset",
                 "_length", "_record")  # fmt: skip

    def __init__(self, name: str, seq: int, start_ns: int, end_ns: int, count: int,
                 segment: Segment, offset: int, length: int):  # fmt: skip
        self.name, self.seq, self.start_ns, self.end_ns, self.count = name, seq, start_ns, end_ns, count
        self._segment, self._offset, self._length = segment, offset, length
        self._record = None

    def _read(self):
        if self._record is None:
            with self._segment.lock:  # the group-commit thread may be flushing this segment
                if self._segment.fd < 0:
                    raise StoreError(f"{self._segment.path} is closed: the store was closed, or compaction "
                                     "replaced or dropped this segment; query again")  # fmt: skip
                self._record = self._segment.read_record(self._offset, self._length)
        return self._record

    @property
    def meta(self) -> dict[str, Any]:
        return json.loads(self._read()[0].meta)

    @property
    def codec_config(self) -> dict[str, Any]:
        return json.loads(self._read()[0].config)

    @property
    def stored_bytes(self) -> int:
        return self._length

    @property
    def flags(self) -> int:
        """The record's flag bits (`cclogfs.format.RecordFlag`)."""
        return self._read()[0].flags

    @property
    def aged(self) -> Any:
        """How the texts differ from what was put (meta key "aged"), or None when byte-exact."""
        header = self._read()[0]
        return json.loads(header.meta).get(AGED_META_KEY) if header.flags & RecordFlag.AGED else None

    def messages(self) -> Iterator[tuple[int, str]]:
        """(stamp_ns, JSON text) of each message, exactly as put."""
        header, payload = self._read()
        codec = codec_from_config(json.loads(header.config))
        if codec_numeric_id(codec) != header.codec:
            raise CorruptionError(
                f"{self._segment.path}: record at offset {self._offset} names codec "
                f"{header.codec} in its header but {codec.codec_id!r} in its config",
                path=self._segment.path, offset=self._offset, reason=Reason.BAD_LENGTH,
            )  # fmt: skip
        stamps, texts = codec.decode(payload, count=header.count, raw_len=header.raw_len)
        return zip(stamps, (t.decode("utf-8") for t in texts))

    def __repr__(self) -> str:
        return f"Window({self.name!r}, seq={self.seq}, {self.start_ns}..{self.end_ns}, count={self.count})"


class Store:
    """A store directory opened by `open_store`. Not for use from several threads at once
    (the group-commit thread is internal and takes the store's lock)."""

    def __init__(self, path: str, fs: FileSystem, readonly: bool, codec: Codec,
                 stream_codecs: Mapping[str, Codec], sync_every_ms: float | None,
                 sync_every_bytes: int | None, segment_bytes: int, segment_age_s: float,
                 segment_records: int):  # fmt: skip
        self.path = path
        self.fs = fs
        self.readonly = readonly
        self.codec = codec
        self.stream_codecs = dict(stream_codecs)
        self.sync_every_ms = sync_every_ms
        self.sync_every_bytes = sync_every_bytes
        self.segment_bytes = segment_bytes
        self.segment_age_s = segment_age_s
        self.segment_records = segment_records
        self.recovery = Recovery()
        self.manifest: dict[str, Any] = {}
        self.sealed: list[Segment] = []  # in seq order
        self.active: Segment | None = None  # writer: the segment appended to
        self.unsealed: list[Segment] = []  # reader: what it saw past the manifest
        self._lock = threading.RLock()
        # One rewrite or drop at a time, from planning to commit: two overlapping rewrites of
        # a segment would both write its next generation.
        self._compaction_lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._lock_fd: int | None = None
        self._failed: BaseException | None = None
        self._closed = False
        self._unsynced_bytes = 0
        self._unsynced_since: float | None = None
        self._flusher: threading.Thread | None = None
        self._sealed_by_stream: dict[str, tuple[np.ndarray, np.ndarray, list[Segment]]] | None = None
        self._codec_headers: dict[int, tuple[Codec, bytes, int]] = {}

    # -- context manager -------------------------------------------------------------------

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _file(self, name: str) -> str:
        return os.path.join(self.path, name)

    # -- opening ---------------------------------------------------------------------------

    def _create(self) -> None:
        self.fs.mkdir(self.path)
        self.manifest = {
            "format_version": FORMAT_VERSION,
            "store_id": uuid.uuid4().hex,
            "created_ns": time.time_ns(),
            "codec": self.codec.get_config(),
            "segments": [],
        }
        self.fs.write_file_atomic(self._file(MANIFEST), pack_manifest(self.manifest))

    def _load_manifest(self) -> bytes:
        """Read and check the manifest; returns its bytes."""
        path = self._file(MANIFEST)
        raw = self.fs.read_file(path)
        try:
            self.manifest = unpack_manifest(raw)
        except RecordError as err:
            raise CorruptionError(f"{path} is damaged: {err}", path=path, offset=0,
                                  reason=err.reason) from err  # fmt: skip
        version = self.manifest.get("format_version")
        if version not in FORMAT_VERSIONS:
            raise StoreError(f"{path}: field format_version is {version!r}, which this cclogfs cannot read "
                             f"(it reads versions {', '.join(map(str, FORMAT_VERSIONS))}); use a newer cclogfs")  # fmt: skip
        return raw

    @property
    def first_seq(self) -> int:
        """Sequence number of the store's first record (> 0 once retention dropped segments)."""
        return self.manifest.get("first_seq", 0)

    def sealed_segments(self) -> list[SealedSegment]:
        """The sealed segments, oldest first, as the manifest names them."""
        with self._lock:
            infos = list(self.manifest.get("segments", ()))
        return [SealedSegment(i["first_seq"], i["end_seq"], i["size"], i.get("gen", 0), i["streams"],
                              i.get("aged", {})) for i in infos]  # fmt: skip

    @property
    def active_first_seq(self) -> int | None:
        """First seq of the segment being written (None for a reader)."""
        active = self.active
        return None if active is None else active.first_seq

    def dropped(self) -> dict[str, Any]:
        """What retention dropped so far: {"segments": n, "streams": {name: stats}} (stats as
        in `streams()`, their time range is what was dropped)."""
        return self.manifest.get("dropped", {"segments": 0, "streams": {}})

    def _open(self, create: bool) -> None:
        manifest_path = self._file(MANIFEST)
        if not self.fs.exists(manifest_path):
            # Only a lock and temporary files: a crash while the store was being created.
            leftovers = [n for n in self.fs.listdir(self.path)] if self.fs.exists(self.path) else []
            if all(n == LOCK or n.endswith(TMP_SUFFIX) for n in leftovers):
                if not create or self.readonly:
                    raise StoreError(f"{self.path} is not a cclogfs store (no {MANIFEST}); "
                                     "pass create=True to make one")  # fmt: skip
            else:
                raise StoreError(f"{self.path} holds files but no {MANIFEST}: not a cclogfs store, "
                                 "or one whose manifest was lost (run `cclog fsck`)")  # fmt: skip
        if not self.readonly:
            self.fs.mkdir(self.path)
            self._take_lock()
        if not self.fs.exists(manifest_path):
            self._create()
        self._load_manifest()
        if not self.readonly:
            for name in self.fs.listdir(self.path):
                if name.endswith(TMP_SUFFIX):  # a crash while replacing a file
                    self.fs.unlink(self._file(name))
                    self.recovery.removed_files.append(name)
        self._open_segments_retrying()
        if not self.readonly:
            self._start_flusher()

    def _take_lock(self) -> None:
        path = self._file(LOCK)
        fd = self.fs.lock(path)
        if fd is None:
            try:
                holder = self.fs.read_file(path).decode(errors="replace").strip() or "unknown"
            except OSError:
                holder = "unknown"
            raise StoreLockedError(f"{self.path} is locked by another writer ({holder}); "
                                   "open it with readonly=True to read")  # fmt: skip
        self._lock_fd = fd
        info = json.dumps({"pid": os.getpid(), "host": socket.gethostname()}).encode()
        self.fs.truncate(fd, 0)
        self.fs.pwrite(fd, info, 0)

    def _open_segments_retrying(self) -> None:
        """Load the manifest and open its segments. A reader retries when a listed segment
        is missing: a writer compacted between its reading the manifest and the files."""
        for attempt in range(5):
            raw = self._load_manifest()
            try:
                self._open_segments()
                # A reader must see files and manifest of one moment: if the manifest
                # changed meanwhile, a segment may have been sealed and rewritten under it.
                if not self.readonly or self.fs.read_file(self._file(MANIFEST)) == raw:
                    return
            except (CorruptionError, FileNotFoundError) as err:
                retry = isinstance(err, FileNotFoundError) or err.reason == "missing segment"
                if not (self.readonly and retry and attempt < 4):
                    raise
            if attempt == 4:
                raise StoreError(f"{self.path}: the store changed under this reader five times "
                                 "while it was opening (a writer compacting); try again")  # fmt: skip
            self._close_segments()
            self.sealed, self.unsealed, self.recovery = [], [], Recovery()

    def _close_segments(self) -> None:
        for seg in self._segments():
            if seg.fd >= 0:
                self.fs.close(seg.fd)
            seg.fd = -1

    def _is_leftover(self, first_seq: int, gen: int, sealed_firsts: set[int]) -> bool:
        """A segment or index file that only an interrupted compaction or retention step
        leaves behind: a generation > 0 the manifest does not name, an older generation of
        a listed segment, or a segment before the store's first (dropped)."""
        return gen > 0 or first_seq in sealed_firsts or first_seq < self.first_seq

    def _open_segments(self) -> None:
        named = {(info["first_seq"], info.get("gen", 0)) for info in self.manifest["segments"]}
        sealed_firsts = {info["first_seq"] for info in self.manifest["segments"]}
        files, tail, leftovers = {}, {}, []
        for name in self.fs.listdir(self.path):
            parsed = parse_seq_name(name)
            if parsed is None:
                continue
            first_seq, kind, gen = parsed
            if (first_seq, gen) in named:
                if kind == "seg":
                    files[first_seq, gen] = name
            elif self._is_leftover(first_seq, gen, sealed_firsts):
                leftovers.append(name)
            elif kind == "seg":
                tail[first_seq] = name
        self.recovery.leftovers = leftovers
        next_seq = self.first_seq
        for info in self.manifest["segments"]:
            gen = info.get("gen", 0)
            name = files.get((info["first_seq"], gen))
            if name is None:
                raise CorruptionError(
                    f"{self.path}: {MANIFEST} lists segment {segment_name(info['first_seq'], gen)}, "
                    "which is missing", path=self._file(MANIFEST), reason="missing segment",
                )  # fmt: skip
            seg, _ok = open_segment(self.fs, self._file(name), write=False, lock=self._lock)
            seg.first_seq, seg.next_seq = info["first_seq"], info["end_seq"]
            seg.sealed_size, seg.gen = info["size"], gen
            self.sealed.append(seg)
            next_seq = info["end_seq"]
        # Only now, with every file the manifest names found, and of the size it states: were
        # one missing or cut short, the other generation might be all that is left of it.
        damaged = {seg.first_seq for seg in self.sealed if seg.size != seg.sealed_size}
        if damaged:
            self.recovery.leftovers = leftovers = [n for n in leftovers if parse_seq_name(n)[0] not in damaged]
        if leftovers and not self.readonly:
            for name in leftovers:
                self.fs.unlink(self._file(name))
                self.recovery.removed_files.append(name)
            self.fs.fsync_dir(self.path)
        self._recover_tail(next_seq, [tail[s] for s in sorted(tail)])

    def _index_path(self, seg: Segment) -> str:
        return self._file(index_name(seg.first_seq, seg.gen))

    def _recover_tail(self, next_seq: int, names: list[str]) -> None:
        """Scan the unsealed segments; keep exactly their valid prefix (see FORMAT.md)."""
        kept: list[Segment] = []
        broken = False
        for name in names:
            path = self._file(name)
            first_seq = parse_seq_name(name)[0]
            if first_seq < next_seq:  # older than the manifest's end: not ours to touch
                self.recovery.problems.append(Problem(path, 0, "stray segment", "ignored"))
                continue
            seg, header_ok = open_segment(self.fs, path, write=not self.readonly, lock=self._lock)
            if broken or first_seq != next_seq:
                reason = Reason.DROPPED_SEGMENT if broken else Reason.SEQ_GAP
                self.recovery.problems.append(Problem(path, 0, reason, "", seg.size))
                self._drop_segment(seg)
                broken = True
                continue
            if not header_ok or seg.first_seq != first_seq:
                # Created but its header never reached the disk: it cannot hold synced data.
                self.recovery.problems.append(Problem(path, 0, Reason.BAD_SEGMENT_HEADER, "", seg.size))
                self._drop_segment(seg)
                broken = True
                continue
            result = scan(seg)
            self.recovery.skipped.extend(result.skipped)
            seg.rows, seg.next_seq = result.rows, result.next_seq
            if result.problem:
                problem = result.problem
                problem.intact_after = intact_after(seg, problem.offset)
                self.recovery.problems.append(problem)
                broken = True
                if not self.readonly:
                    if problem.intact_after:
                        problem.kept_in = self._keep_tail(seg, problem.offset)
                    self.fs.truncate(seg.fd, result.end)
                    self.fs.fsync(seg.fd)
                seg.size = result.end
            kept.append(seg)
            next_seq = seg.next_seq
        if self.readonly:
            self.unsealed = kept
            return
        for seg in kept[:-1]:  # a crash while sealing left it complete but unsealed
            self._seal(seg)
            self.recovery.sealed_on_open.append(os.path.basename(seg.path))
        self.active = kept[-1] if kept else self._new_segment(next_seq)

    def _keep_tail(self, seg: Segment, offset: int) -> str:
        """Copy the bytes recovery is about to cut to a side file, when intact records lie
        among them: they were written but perhaps never synced (a reordered write), or a
        synced record was damaged (bit rot). The log keeps its prefix guarantee either
        way, and no byte is destroyed."""
        name = f"{os.path.basename(seg.path)}.tail-{offset}"
        data = self.fs.pread(seg.fd, self.fs.size(seg.fd) - offset, offset)
        self.fs.write_file_atomic(self._file(name), data)
        return name

    def _drop_segment(self, seg: Segment) -> None:
        self.fs.close(seg.fd)
        if not self.readonly:
            self.fs.unlink(seg.path)
            self.fs.fsync_dir(self.path)
            self.recovery.removed_files.append(os.path.basename(seg.path))

    def _new_segment(self, first_seq: int) -> Segment:
        path = self._file(segment_name(first_seq))
        created = time.time_ns()
        fd = self.fs.open(path, write=True, create=True)
        self.fs.pwrite(fd, pack_segment_header(first_seq, created), 0)
        self.fs.fsync(fd)
        self.fs.fsync_dir(self.path)
        return Segment(self.fs, path, first_seq, created, fd, SEGMENT_HEADER_SIZE, lock=self._lock)

    # -- writing ---------------------------------------------------------------------------

    def _check_writable(self) -> None:
        if self._closed:
            raise StoreError(f"{self.path}: the store is closed")
        if self.readonly:
            raise StoreError(f"{self.path} was opened read-only")
        if self._failed is not None:
            raise StoreFailedError(
                f"{self.path}: an earlier write or fsync failed ({self._failed}); the store "
                "refuses further writes because what reached the disk is unknown; reopen it to recover"
            ) from self._failed

    def put_window(self, name: str, messages: Sequence[tuple[int, str]],
                   meta: Mapping[str, Any] | None = None, *, codec: Any = None,
                   check_json: bool = True) -> Receipt:  # fmt: skip
        """Store one window of messages (stamp_ns, JSON text) for stream `name`.

        Everything is checked before anything is written: bad input raises
        InvalidInputError and stores nothing. `check_json=False` skips only the JSON parse,
        for texts a parser has just checked (a JSONL or bag source); the text is still
        stored and returned byte for byte.
        """
        if meta is not None and AGED_META_KEY in meta:
            raise InvalidInputError(f"{self.path}: window meta key {AGED_META_KEY!r} is reserved: compaction "
                                    "writes it, with the AGED flag, to say how a window was aged")  # fmt: skip
        enc = self._encode_window(name, messages, meta, codec, check_json)
        stamps, raw_len = enc.stamps, enc.raw_len
        with self._lock:
            self._check_writable()
            seg = self.active
            seq = seg.next_seq
            record = enc.pack(seq)
            row = (name, len(stamps), seq, stamps[0], stamps[-1], seg.end, len(record), raw_len)
            if self._unsynced_since is None:  # before the append: a commit must never skip its fsync
                self._unsynced_since = time.monotonic()
            try:
                seg.append(record, row)
            except OSError as err:
                self._failed = err
                raise StoreFailedError(f"{seg.path}: write failed: {err}") from err
            self._unsynced_bytes += len(record)
            # A full segment is committed (and so sealed) at once, not at the next group
            # commit: the limits bound what recovery must scan.
            if self._commit_due() or seg.end >= self.segment_bytes or len(seg.rows) >= self.segment_records:
                self._commit()
            return Receipt(seq, name, stamps[0], stamps[-1], len(stamps), raw_len, len(record))

    def _encode_window(self, name: str, messages: Sequence[tuple[int, str]], meta: Mapping[str, Any] | None,
                       codec: Any, check_json: bool) -> _Encoded:  # fmt: skip
        """Check and encode a window (everything but its seq and flags); raises InvalidInputError."""
        name_bytes = check_stream_name(name)
        stamps, texts = encode_messages(messages, check_json=check_json)
        meta_bytes = b"{}" if meta is None else _encode_meta(meta)
        chosen = codec_from_config(codec) if codec is not None else self.stream_codecs.get(name, self.codec)
        config, codec_number = self._codec_header(chosen)
        raw_len = raw_size(stamps, texts)
        if raw_len > MAX_RAW:
            raise InvalidInputError(f"window for {name!r} is {raw_len} bytes, over the {MAX_RAW}-byte "
                                    "record limit; split it into several windows")  # fmt: skip
        return _Encoded(name_bytes, stamps, meta_bytes, config, codec_number, raw_len, chosen.encode(stamps, texts))

    def _codec_header(self, codec: Codec) -> tuple[bytes, int]:
        """The config bytes and number that go in each record, cached per codec object."""
        cached = self._codec_headers.get(id(codec))
        if cached is None or cached[0] is not codec:
            config = json.dumps(codec.get_config(), separators=(",", ":")).encode()
            if len(config) > MAX_CONFIG:
                raise InvalidInputError(f"codec config is {len(config)} bytes, over {MAX_CONFIG}")
            cached = (codec, config, int(codec_numeric_id(codec)))
            if codec is self.codec or codec in self.stream_codecs.values():
                self._codec_headers[id(codec)] = cached
        return cached[1], cached[2]

    def _commit_due(self) -> bool:
        if self.sync_every_ms is not None and (
            self.sync_every_ms == 0
            or (time.monotonic() - self._unsynced_since) * 1000 >= self.sync_every_ms
        ):
            return True
        return self.sync_every_bytes is not None and self._unsynced_bytes >= self.sync_every_bytes

    def sync(self) -> None:
        """Make every put before this call durable (one fsync for the whole group)."""
        with self._lock:
            self._check_writable()
            self._commit()

    def _commit(self) -> None:
        seg = self.active
        try:
            seg.flush()
            if self._unsynced_since is not None:
                self.fs.fsync(seg.fd)
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
        with self._lock:
            self._check_writable()
            sealed = len(self.sealed)
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
        return compaction.rewrite(self, fn, segments)

    def drop_oldest(self) -> Dropped | None:
        """Retention: remove the oldest sealed segment (never the active one); None when
        there is no sealed segment. The log then starts at the next segment's first seq."""
        return compaction.drop_oldest(self)

    def _seal(self, seg: Segment) -> None:
        """Write the segment's index, then name it in the manifest (it is already synced)."""
        index = seg.index()
        self.fs.write_file_atomic(self._index_path(seg), index.encode(seg.first_seq, seg.size))
        info = {"first_seq": seg.first_seq, "end_seq": seg.next_seq, "size": seg.size,
                "streams": index.stream_stats()}  # fmt: skip
        manifest = dict(self.manifest, segments=[*self.manifest["segments"], info])
        self.fs.write_file_atomic(self._file(MANIFEST), pack_manifest(manifest))
        self.manifest = manifest
        seg.sealed_size = seg.size
        self.sealed.append(seg)
        self._sealed_by_stream = None

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
        with self._lock:
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
        with self._lock, _signals_deferred():  # a second Ctrl-C must not skip the last fsync
            if self._closed:
                return
            try:
                if not self.readonly and self._failed is None:
                    self._commit()
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
        """The sealed segment's index from its .idx file, rebuilt when missing or damaged."""
        if seg._index is None:
            if seg.size != seg.sealed_size:
                # Never answer from a sealed segment that lost or gained bytes: a shorter one
                # would otherwise give a silent hole.
                raise CorruptionError(f"{seg.path} is {seg.size} bytes but the manifest says it was sealed "
                                      f"at {seg.sealed_size}; its records cannot be trusted (run `cclog fsck`)",
                                      path=seg.path, offset=min(seg.size, seg.sealed_size),
                                      reason=Reason.BAD_LENGTH)  # fmt: skip
            path = self._index_path(seg)
            try:
                seg._index = SegmentIndex.decode(self.fs.read_file(path), seg.first_seq, seg.size)
            except (OSError, RecordError, ValueError, TypeError):
                result = scan(seg)
                problem = result.problem
                if problem is None and result.next_seq != seg.next_seq:
                    problem = Problem(seg.path, result.end, Reason.SEQ_GAP,
                                      f"ends at seq {result.next_seq}, the manifest says {seg.next_seq}")  # fmt: skip
                if problem:
                    raise CorruptionError(f"{seg.path}: cannot rebuild the time index: {problem}",
                                          path=seg.path, offset=problem.offset, reason=problem.reason)  # fmt: skip
                seg._index = SegmentIndex.build(result.rows)
                if not self.readonly and not self._closed:
                    self.fs.write_file_atomic(path, seg._index.encode(seg.first_seq, seg.size))
        return seg._index

    def _sealed_candidates(self, name: str, t0: int, t1: int) -> list[Segment]:
        """Sealed segments whose stream `name` may overlap [t0, t1], by binary search."""
        if self._sealed_by_stream is None:
            by_stream: dict[str, list[tuple[int, int, Segment]]] = {}
            for seg, info in zip(self.sealed, self.manifest["segments"]):
                for stream, st in info["streams"].items():
                    by_stream.setdefault(stream, []).append((st["start_ns"], st["end_ns"], seg))
            self._sealed_by_stream = {}
            for stream, items in by_stream.items():
                items.sort(key=lambda x: (x[0], x[2].first_seq))
                starts = np.array([i[0] for i in items], dtype=np.int64)
                run_max = np.maximum.accumulate(np.array([i[1] for i in items], dtype=np.int64))
                self._sealed_by_stream[stream] = (starts, run_max, [i[2] for i in items])
        found = self._sealed_by_stream.get(name)
        if found is None:
            return []
        starts, run_max, segs = found
        return segs[overlap_slice(starts, run_max, t0, t1)]

    def streams(self) -> dict[str, dict[str, int]]:
        """Per stream: windows, messages, start_ns, end_ns, raw_bytes, stored_bytes, json_bytes,
        aged (windows flagged AGED)."""
        with self._lock:
            infos = list(self.manifest["segments"])
            per_segment = [info["streams"] for info in infos]
            per_segment += [seg.index().stream_stats() for seg in self._segments()[len(self.sealed):]]
        total: dict[str, dict[str, int]] = {}
        for stats in per_segment:
            merge_stream_stats(total, stats)
        for name, t in total.items():  # the messages' own JSON, without the framing's lengths and stamps
            t["json_bytes"] = t["raw_bytes"] - 4 * t["windows"] - 12 * t["messages"]
            t["aged"] = sum(info.get("aged", {}).get(name, 0) for info in infos)
        return dict(sorted(total.items()))

    def query(self, name: str | None = None, start_ns: int | None = None,
              end_ns: int | None = None) -> Iterator[Window]:  # fmt: skip
        """Windows of stream `name` (all streams when None) overlapping [start_ns, end_ns],
        in (start_ns, seq) order. Includes this writer's puts not yet synced."""
        t0 = MIN_NS if start_ns is None else int(start_ns)
        t1 = MAX_NS if end_ns is None else int(end_ns)
        with self._lock:
            if self._closed:
                raise StoreError(f"{self.path}: the store is closed")
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
                        if len(hits):
                            runs.append([(int(e["start"]), int(e["seq"]), stream, e, seg) for e in hits])
        for start, seq, stream, e, seg in heapq.merge(*runs, key=lambda r: (r[0], r[1])):
            yield Window(stream, seq, start, int(e["end"]), int(e["count"]), seg,
                         int(e["offset"]), int(e["length"]))  # fmt: skip

    def refresh(self) -> None:
        """Reader: see what the writer has committed since this store was opened."""
        if not self.readonly:
            raise StoreError(f"{self.path}: refresh() is for readers; the writer always sees its own puts")
        with self._lock:
            if self._closed:
                raise StoreError(f"{self.path}: the store is closed")
            # Windows already handed out keep their segment objects; once closed here they
            # say so rather than read a generation compaction may have deleted.
            self._close_segments()
            self.sealed, self.unsealed, self._sealed_by_stream = [], [], None
            self.recovery = Recovery()
            self._open_segments_retrying()

    def data_bytes(self) -> int:
        """Bytes of the store's own files (manifest, segments, indexes): what a storage
        budget counts. Recovery's side files (`.seg.tail-N`) and other strays are left out,
        so evidence kept for a repair never makes retention drop data."""
        total = 0
        for name in self.fs.listdir(self.path):
            if name == MANIFEST or parse_seq_name(name) is not None:
                try:
                    total += os.path.getsize(self._file(name))
                except FileNotFoundError:  # removed meanwhile (a writer compacting while we read)
                    pass
        return total

    def disk_bytes(self) -> int:
        """Bytes of every file in the store directory."""
        total = 0
        for name in self.fs.listdir(self.path):
            try:
                total += os.path.getsize(self._file(name))
            except FileNotFoundError:  # removed meanwhile (a writer compacting while we read)
                pass
        return total


@dataclass(frozen=True, slots=True)
class _Encoded:
    """A checked, encoded window waiting for its seq and flags."""

    name: bytes
    stamps: list[int]
    meta: bytes
    config: bytes
    codec: int
    raw_len: int
    payload: bytes

    def pack(self, seq: int, flags: int = 0) -> bytes:
        return pack_record(
            seq=seq, start_ns=self.stamps[0], end_ns=self.stamps[-1], count=len(self.stamps),
            codec=self.codec, name=self.name, config=self.config, meta=self.meta,
            raw_len=self.raw_len, payload=self.payload, flags=flags,
        )  # fmt: skip


def _encode_meta(meta: Mapping[str, Any]) -> bytes:
    if not isinstance(meta, Mapping):
        raise InvalidInputError(f"meta must be a dict, got {type(meta).__name__}")
    try:
        data = json.dumps(dict(meta), separators=(",", ":"), allow_nan=False).encode()
    except (TypeError, ValueError) as err:
        raise InvalidInputError(f"meta is not JSON-serializable: {err}") from err
    if len(data) > MAX_META:
        raise InvalidInputError(f"meta is {len(data)} bytes as JSON, over the {MAX_META}-byte limit")
    return data


def open_store(path: str | os.PathLike[str], *, create: bool = False, readonly: bool = False,
               codec: Any = "columnar", stream_codecs: Mapping[str, Any] | None = None,
               sync_every_ms: float | None = 200, sync_every_bytes: int | None = 4 << 20,
               segment_bytes: int = 64 << 20, segment_age_s: float = 3600.0,
               segment_records: int = 16384, fs: FileSystem | None = None) -> Store:  # fmt: skip
    """Open (or with create=True make) the store at `path`; recovers after a crash.

    codec: default codec (id or config dict) for new records; stream_codecs: per-stream
    overrides. sync_every_ms / sync_every_bytes: the group-commit policy (see FORMAT.md).
    segment_bytes / segment_records / segment_age_s: when the active segment is sealed; they
    bound what recovery has to scan after a crash.
    """
    if sync_every_ms is not None and sync_every_ms < 0:
        raise InvalidInputError("sync_every_ms must be >= 0 or None")
    if segment_bytes < 4096 or segment_records < 1:
        raise InvalidInputError("segment_bytes must be at least 4096 and segment_records at least 1")
    store = Store(
        os.fspath(path), fs or FileSystem(), readonly, codec_from_config(codec),
        {k: codec_from_config(v) for k, v in (stream_codecs or {}).items()},
        sync_every_ms, sync_every_bytes, segment_bytes, segment_age_s, segment_records,
    )  # fmt: skip
    for name in store.stream_codecs:
        check_stream_name(name)
    try:
        store._open(create)
    except BaseException:
        store._closed = True
        store._close_segments()
        if store._lock_fd is not None:
            store.fs.unlock(store._lock_fd)
        raise
    return store

