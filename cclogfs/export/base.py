"""What an exporter consumes: windows as the store's `query()` returns them."""

from __future__ import annotations

import dataclasses
import heapq
import itertools
import os
import re
import shutil
import time
from collections.abc import Callable, Iterable, Iterator
from operator import attrgetter
from pathlib import Path
from typing import Any, Protocol

from ..windowcount import CountedTotals, Link, WindowCount, count_records, link_of

# Called with the number of messages just written, for progress bars.
Progress = Callable[[int], None]


def work_file(path: str | Path) -> Path:
    """A new empty file beside `path`, named for it and unique, to write an output in before
    it is renamed over `path`. Unique: two exports to one output at once each have their own
    (a fixed OUT.tmp was shared, so each wrote into the other's file, and a file of the user's
    by that name was overwritten). Made with mode 0666 less the umask, as a new file is, not
    mkstemp's 0600: the rename makes it the output others read. The name holds the writer's
    pid, so that the next run removes what a killed one left (`remove_stale_work_files`)."""
    path = Path(path)
    remove_stale_work_files(path)
    for _ in range(100):
        tmp = path.with_name(f".{path.name}.{os.getpid()}.{os.urandom(4).hex()}.tmp")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return tmp
    raise FileExistsError(f"no free work file name beside {path}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: alive, another user's
        return True
    return True


# A work file of an older version holds no pid (`.OUT.XXXXXXXX.tmp`: mkstemp's, or
# work_file's before the pid): one untouched this long is taken for a killed writer's, as a
# live one writes on (were it only stalled, its rename fails, loudly).
OLD_WORK_FILE_S = 3600


def remove_stale_work_files(path: str | Path) -> list[Path]:
    """Remove the work files of `path` whose writer's pid is not alive (an export or convert
    killed before its rename left a hidden `.OUT.PID.XXXXXXXX.tmp`, a file, or a directory for
    a rosbag2 bag; a Parquet export `.OUT.partial-PID`, and `.OUT.old-PID` once `path` is
    back); those of a live writer (a concurrent export to the same output) stay, as does
    any not named so (OUT.tmp may be the user's). An older version's, without a pid, goes
    once untouched for OLD_WORK_FILE_S. Which were removed."""
    path = Path(path)
    name = re.escape(path.name)
    # .OUT.PID.X.tmp (X: work_file's 8 hex digits or mkdtemp's 8 letters, a rosbag2 export's
    # directory), .OUT.partial-PID, .OUT.old-PID (Parquet), .OUT.X.tmp (an older version's)
    pattern = re.compile(rf"\.{name}\.(?:(\d+)\.[0-9a-z_]{{8}}\.tmp|partial-(\d+)|old-(\d+)|([0-9a-z_]{{8}})\.tmp)")
    removed = []
    folder = path.parent if str(path.parent) else Path(".")
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for entry in names:
        if (m := pattern.fullmatch(entry)) is None:
            continue
        stale = folder / entry
        if not _stale(stale, m, path):
            continue
        try:
            if stale.is_dir() and not stale.is_symlink():
                shutil.rmtree(stale)
            else:
                stale.unlink()
        except FileNotFoundError:
            continue  # another run removed it first
        removed.append(stale)
    return removed


def _stale(work: Path, m: re.Match, path: Path) -> bool:
    """Whether the work file `work` (matched by `m`) of output `path` is a dead writer's."""
    pid, partial, old_pid, nopid = m.groups()
    if nopid is not None:  # an older version's: its writer cannot be told, only its age
        try:
            return time.time() - work.lstat().st_mtime > OLD_WORK_FILE_S
        except FileNotFoundError:
            return False
    if old_pid is not None and not path.exists():
        return False  # killed between the renames: the previous export, the only one there is
    return not _alive(int(pid or partial or old_pid))


def commit_work_file(tmp: str | Path, path: str | Path) -> None:
    """Rename the finished work file (or directory) `tmp` over `path` durably: its data
    synced before the rename (else a power cut could leave an empty or partial file under the
    final name) and the directory after (else the rename itself could be lost), as the store
    does."""
    if os.path.isdir(tmp):
        for name in os.listdir(tmp):
            fsync_path(os.path.join(tmp, name))
    fsync_path(tmp)
    os.replace(tmp, path)
    fsync_path(os.path.dirname(os.path.abspath(path)))


def fsync_path(path: str | Path) -> None:
    """fsync a file or directory by name."""
    fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if os.path.isdir(path) else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class StoredWindow(Protocol):
    """One stored window of one stream: the read shape of the store's `Window`.

    A Protocol, not the store's class: an exporter needs only this shape, so export does
    not depend on the storage engine and any iterable of such windows (a query, a test's
    fake, a filter over a query) can be exported.
    """

    name: str
    seq: int
    start_ns: int
    end_ns: int
    meta: dict[str, Any]

    def messages(self) -> Iterator[tuple[int, str]]:
        """(stamp_ns, exact JSON text) of each message, in time order."""
        ...


@dataclasses.dataclass
class ExportStats(CountedTotals):
    """What an export wrote. `windows` counts a logging window once however many records
    hold it (`windowcount`: a smart window's parts, a window whose stamps go back, a record
    the store split over its 16 MiB limit), as `cclog record` and `cclog info` count them,
    the recorder's summaries apart (`summaries`); `records` counts the records of `windows`.
    With --start/--end a window counts when any record of it is written."""

    messages: int = 0
    streams: set[str] = dataclasses.field(default_factory=set)
    files: list[str] = dataclasses.field(default_factory=list)
    # (seq, stream, link, flagged PART) of each record written, counted when asked
    _written: list[tuple[int, str, Link, bool]] = dataclasses.field(default_factory=list, repr=False)
    _count: tuple[int, WindowCount] | None = dataclasses.field(default=None, repr=False, compare=False)

    def wrote(self, w: StoredWindow, count: int) -> None:
        """`count` messages of the stored record `w` were written (in any order)."""
        self._written.append((w.seq, w.name, link_of(w.meta), bool(getattr(w, "continues", False))))
        self.messages += count
        self.streams.add(w.name)

    @property
    def counted(self) -> WindowCount:
        """The windows of the records written so far (`windowcount.count_records`)."""
        if self._count is None or self._count[0] != len(self._written):
            self._count = len(self._written), count_records(self._written)
        return self._count[1]


@dataclasses.dataclass(frozen=True)
class ClippedWindow:
    """A stored window cut to a time range: the messages of it that `cat --start/--end` prints."""

    name: str
    seq: int
    start_ns: int
    end_ns: int
    meta: dict[str, Any]
    held: list[tuple[int, str]]
    continues: bool = False  # the stored record's: its window goes on in the next record

    def messages(self) -> Iterator[tuple[int, str]]:
        return iter(self.held)


@dataclasses.dataclass
class Clip:
    """Windows cut to [start_ns, end_ns] (either None: open), both ends included as in `cat`.

    A window wholly inside passes as it is (its messages are not read here); one that
    reaches past an end keeps its messages in the range (`ClippedWindow`), and is left out
    when none is. `cut` counts the windows cut and kept, `left_out` the messages outside
    the range that the windows selected held."""

    start_ns: int | None
    end_ns: int | None
    cut: int = 0
    left_out: int = 0

    def __call__(self, windows: Iterator[StoredWindow]) -> Iterator[StoredWindow]:
        """The windows cut, still in start order (which `merged_runs` needs): a window that
        starts before `start_ns` starts at its first message kept once cut, maybe after
        windows the query gives after it. Those come first (they start before all others),
        and overlap `start_ns`, so they are few: held, then merged in by their new start."""
        lo = -(1 << 63) if self.start_ns is None else self.start_ns
        it = iter(windows)
        early: list[StoredWindow] = []
        for w in it:
            if w.start_ns >= lo:
                it = itertools.chain([w], it)
                break
            early += self._cut([w])
        early.sort(key=attrgetter("start_ns"))
        yield from heapq.merge(early, self._cut(it), key=attrgetter("start_ns"))

    def _cut(self, windows: Iterable[StoredWindow]) -> Iterator[StoredWindow]:
        lo = -(1 << 63) if self.start_ns is None else self.start_ns
        hi = (1 << 63) if self.end_ns is None else self.end_ns
        for w in windows:
            if lo <= w.start_ns and w.end_ns <= hi:
                yield w
                continue
            every = list(w.messages())
            held = [m for m in every if lo <= m[0] <= hi]
            self.left_out += len(every) - len(held)
            if held:
                self.cut += 1
                stamps = [s for s, _ in held]  # a split window's stamps go back: min/max, not ends
                yield ClippedWindow(w.name, w.seq, min(stamps), max(stamps), w.meta, held,
                                    getattr(w, "continues", False))
