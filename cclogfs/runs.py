"""Recording runs: who put what into a store, from which source, with which options.

Each `cclog record` is a *run*, kept as two JSON texts on the bookkeeping stream
`/cclog/runs` (docs/JSON.md, "The runs stream"): a start record written and synced before
the first message is stored, and an end record written when the run closes. A run killed
with SIGKILL or cut by a power loss has no end record, so it is still seen, as unfinished.
Being ordinary windows, the records share the store's checksums, crash recovery and fsck;
no new file kind. Readers (`cat`, `export`, `play`, `plot`) leave the stream out unless it
is named (`hidden_by_default`), so a store's messages read back exactly as they were put.

A file source is identified by a fingerprint of its content (size and SHA-256 of its first
and last MiB, per file for a ROS 2 bag directory), not by its path: a copy of a bag is the
same source, a bag rewritten under the same name is not. `earlier_run` finds the run that
recorded a source already, so that the CLI can refuse to store it twice. The checks take
the runs `list_runs` read (a query and a decode of the whole stream), so that `record`
reads them once.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from . import __version__
from .growth import EDGE as _EDGE
from .growth import head as _head

if TYPE_CHECKING:
    from .store import Store

# hashlib, socket and uuid are imported by the functions of `record` that use them: every
# reader imports this module for `hidden_by_default`, and they were a tenth of its start-up.

RUNS_STREAM = "/cclog/runs"
# _EDGE: bytes hashed at each end of a file: cheap on a 10 GB bag, and a bag's header
# (first MiB) and index (last MiB) differ between any two recordings

__all__ = ["RUNS_STREAM", "Run", "RunInfo", "begin_run", "content_key", "earlier_run", "grown_run",
           "has_fingerprint", "hidden_by_default", "list_runs", "runs_damage", "source_fingerprint"]  # fmt: skip


def hidden_by_default(name: str) -> bool:
    """A stream readers leave out unless asked for it by name: bookkeeping, not messages."""
    return name == RUNS_STREAM


def _hash_file(path: str, h: Any) -> int:
    """Feed a file's size, first and last MiB into `h`; its size."""
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        h.update(size.to_bytes(8, "little"))
        h.update(f.read(_EDGE))
        if size > _EDGE:
            f.seek(max(size - _EDGE, _EDGE))
            h.update(f.read(_EDGE))
    return size


def has_fingerprint(path: str) -> bool:
    """Whether the source `path` has fixed content to fingerprint (not stdin, not live)."""
    return path != "-" and "://" not in path


def source_fingerprint(path: str) -> dict[str, Any] | None:
    """What identifies a file or ROS 2 bag directory's content; None for what has no
    fixed content (stdin `-`, a live `ros1://` source)."""
    if not has_fingerprint(path):
        return None
    import hashlib

    h = hashlib.sha256()
    if os.path.isdir(path):  # a ROS 2 bag: metadata.yaml and its storage files
        names = sorted(os.path.join(d, f) for d, _, files in os.walk(path) for f in files)
        size = 0
        for name in names:
            h.update(os.path.relpath(name, path).encode() + b"\0")
            size += _hash_file(name, h)
        return {"bytes": size, "files": len(names), "sha256": h.hexdigest()}
    size = _hash_file(path, h)
    # "head": to know the file again once it has grown (a bag closed since, say: growth.head)
    return {"bytes": size, "sha256": h.hexdigest(), "head": _head(path, size)}


def content_key(fingerprint: Mapping[str, Any]) -> tuple:
    """What of a fingerprint names its content: "head" is left out, since runs recorded
    before it was kept have none."""
    return tuple(fingerprint.get(k) for k in ("bytes", "files", "sha256"))


def _same_content(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Fingerprints of one content (`content_key`)."""
    return content_key(a) == content_key(b)


@dataclass
class RunInfo:
    """One run of a store, from its start record and (when it has one) its end record."""

    number: int
    id: str
    start_ns: int
    source: str
    fingerprint: dict[str, Any] | None
    options: dict[str, Any]
    start: dict[str, Any] = field(repr=False)
    end: dict[str, Any] | None = None
    end_ns: int | None = None
    # Seqs the start and end records were first put under (retention carries them to new
    # ones: store.carry): the run's windows lie between them.
    start_seq: int = -1
    end_seq: int | None = None
    first_seq: int = 0  # the store's first seq: retention dropped every window before it

    @property
    def retention(self) -> str | None:
        """"all dropped" or "some dropped" when retention dropped windows this run kept
        (its records outlive them), else None."""
        if self.kept == 0 or self.first_seq <= self.start_seq + 1:
            return None
        return "all dropped" if self.end_seq is not None and self.first_seq >= self.end_seq else "some dropped"

    @property
    def status(self) -> str:
        """done, interrupted (Ctrl-C/SIGTERM), error, or unfinished: no end record (killed,
        lost power, the disk full or failing when the end was due, or still recording)."""
        return "unfinished" if self.end is None else self.end.get("status", "done")

    @property
    def kept(self) -> int | None:
        return None if self.end is None else self.end.get("messages_kept")

    def as_dict(self) -> dict[str, Any]:
        """The run as `cclog info --json` prints it."""
        out = {"run": self.number, "id": self.id, "start_ns": self.start_ns, "end_ns": self.end_ns,
               "status": self.status, **{k: v for k, v in self.start.items() if k not in ("event", "run", "id")},
               **{k: v for k, v in (self.end or {}).items() if k not in ("event", "run", "id", "status")},
               "source": self.source, "options": self.options}  # fmt: skip
        if self.retention:
            out["retention"] = self.retention
        return out


def list_runs(store: Store) -> list[RunInfo]:
    """The store's runs in start order. Damaged records are left out (the store names its
    damage; `cclog info` prints it); a record that is not a run's JSON is skipped."""
    from .store.carry import origin

    runs: dict[str, RunInfo] = {}
    for w in store.query(RUNS_STREAM, skip_damaged=True):
        seq = origin(w.meta, w.seq)
        for stamp, text in w.messages():
            try:
                rec = json.loads(text)
                if rec.get("event") == "start":
                    # Another tool's start record may lack the fields ours has, or hold
                    # them in other shapes: the run is listed with what it says.
                    options = rec.get("options")
                    runs[rec["id"]] = RunInfo(int(rec["run"]), rec["id"], stamp, str(rec.get("source", "?")),
                                              rec.get("fingerprint"), options if isinstance(options, dict) else {},
                                              rec, start_seq=seq, first_seq=store.first_seq)  # fmt: skip
                elif rec.get("event") == "end" and rec.get("id") in runs:
                    runs[rec["id"]].end, runs[rec["id"]].end_ns, runs[rec["id"]].end_seq = rec, stamp, seq
            except (ValueError, KeyError, TypeError, AttributeError):
                continue  # someone else's text on the stream: not a run
    return sorted(runs.values(), key=lambda r: (r.start_ns, r.number))


def earlier_run(runs: Sequence[RunInfo], fingerprint: Mapping[str, Any] | None) -> RunInfo | None:
    """The first of `runs` (`list_runs`) that recorded a source with this fingerprint and may
    have kept some of it (a run that ended keeping nothing does not count); None for none,
    or no fingerprint."""
    if fingerprint is None:
        return None
    for run in runs:
        if run.fingerprint is not None and _same_content(run.fingerprint, fingerprint) and run.kept != 0:
            return run
    return None


def runs_damage(store: Store) -> list[dict[str, Any]]:
    """The store's named damage (`Store.damage()`) that may have lost a run's record: a
    stretch that lost seqs and whose first record's header is unreadable, or names
    /cclog/runs, or that lost more than one seq (the later records' streams are unknown). Without those records
    `earlier_run` cannot tell whether a source was recorded."""
    return [d for d in store.damage() if d["end_seq"] > d["first_seq"]  # a segment header that lost no record
            and (d["end_seq"] - d["first_seq"] > 1 or _damaged_stream(store, d) in (None, RUNS_STREAM))]  # fmt: skip


def _damaged_stream(store: Store, d: Mapping[str, Any]) -> str | None:
    """The stream the damaged record at `d` names in its header, when its header checks."""
    from .store.format import RECORD_FIXED_SIZE, RecordError, check_fixed, parse_header

    try:
        with open(os.path.join(store.path, d["segment"]), "rb") as f:
            size = os.fstat(f.fileno()).st_size
            f.seek(d["offset"])
            header_len = check_fixed(f.read(RECORD_FIXED_SIZE), size - d["offset"])
            f.seek(d["offset"])
            return parse_header(f.read(header_len)).name
    except (OSError, RecordError):
        return None


def grown_run(runs: Sequence[RunInfo], path: str, fingerprint: Mapping[str, Any] | None) -> RunInfo | None:
    """The first of `runs` (`list_runs`) that recorded `path` (a file; a ROS 2 bag directory: `_bag_run`) when it was shorter: the file begins with
    what that run saw (an appended log, or a bag recorded in writing, recorded again), so
    recording it would store that run's messages twice. Judged by `growth.head` of the
    first min(size, 1 MiB) bytes the run saw: for a ROS 1 bag its records past the bag
    header (which closing rewrites), for a .db3 its first message row."""
    if fingerprint is not None and "files" in fingerprint:  # a ROS 2 bag directory
        return _bag_run(runs, path)
    if fingerprint is None or "head" not in fingerprint:
        return None
    size = fingerprint["bytes"]
    for run in runs:
        old = run.fingerprint or {}
        if run.kept == 0 or not isinstance(old.get("bytes"), int) or not old.get("head") or not old["bytes"] < size:
            continue
        if _head(path, old["bytes"]) == old["head"]:
            return run
    return None


def _bag_run(runs: Sequence[RunInfo], path: str) -> RunInfo | None:
    """The first run of the ROS 2 bag directory `path` (by its absolute path) that kept
    messages, its content changed since (else `earlier_run` finds it): a bag recorded while
    its recorder was still writing has grown (a .db3 added or longer), and a .db3's bytes
    change where sqlite keeps its header, so no head of a file can tell; a bag directory
    holds one recording (`ros2 bag record -o` refuses an existing one)."""
    return _first_run_of(runs, path, lambda run: "files" in (run.fingerprint or {}))


def stopped_run(runs: Sequence[RunInfo], path: str) -> RunInfo | None:
    """The first of `runs` (`list_runs`) of the file `path` (by its absolute path) that stopped before its end
    (error, interrupted, or no end record) having kept messages: recording the file again
    once fixed (its bad line, say) would store those twice, and its new content hides it
    from `earlier_run`. A run that finished is not one: a file rewritten under the same name
    holds a new recording."""
    return _first_run_of(runs, path, lambda run: run.status != "done")


def _first_run_of(runs: Sequence[RunInfo], path: str, matches: Callable[[RunInfo], bool]) -> RunInfo | None:
    """The first of `runs` of the source `path` (by its absolute path, as `cclog record` names a file)
    that kept messages and `matches`."""
    name = os.path.abspath(path)
    for run in runs:
        if run.source == name and run.kept != 0 and matches(run):
            return run
    return None


class Run:
    """A run in progress: `begin_run` wrote its start; `end()` writes its end."""

    def __init__(self, store: Store, number: int, run_id: str):
        self.store, self.number, self.id = store, number, run_id
        self.ended = False

    def end(self, status: str = "done", **counts: Any) -> None:
        """Write the end record (`status`: done, interrupted or error; `counts`: what the
        run saw, e.g. messages_in, messages_kept, windows, error) and sync it. Once only."""
        if self.ended:
            return
        self.ended = True
        rec = {"event": "end", "run": self.number, "id": self.id, "status": status, **counts}
        self.store.put_window(RUNS_STREAM, [(time.time_ns(), json.dumps(rec))], {"kind": "run"})
        self.store.sync()


def begin_run(store: Store, source: str, *, fingerprint: Mapping[str, Any] | None = None,
              options: Mapping[str, Any] | None = None, runs: Sequence[RunInfo] | None = None,
              **extra: Any) -> Run:  # fmt: skip
    """Write a run's start record (source, fingerprint, options, cclog version, host, pid,
    and `extra`, e.g. the master of a live source) and sync it, so that even a run killed
    at once is seen. Its number is one past the highest of `runs` (the store's, read now
    when not given)."""
    import socket
    import uuid

    if runs is None:
        runs = list_runs(store)
    number = max((r.number for r in runs), default=0) + 1
    run = Run(store, number, uuid.uuid4().hex)
    rec = {"event": "start", "run": number, "id": run.id, "source": source,
           "fingerprint": None if fingerprint is None else dict(fingerprint),
           "options": dict(options or {}), "cclog": __version__, "host": socket.gethostname(),
           "pid": os.getpid(), **extra}  # fmt: skip
    store.put_window(RUNS_STREAM, [(time.time_ns(), json.dumps(rec))], {"kind": "run"})
    store.sync()
    return run
