"""Reading a ROS 2 sqlite3 bag the bag reader refuses: a bag directory whose metadata.yaml
was never written (the recorder died; `ros2 bag reindex` is ROS's answer), or a .db3 cut
short by a power loss. The `topics` and `messages` tables are read directly, row by row where
sqlite reports damage, and the messages come in timestamp order as rosbag2 plays them.

After iterating, `lost` says which rows could not be read (None when every row was), and
`note` that the bag was read without its metadata.yaml.
"""

from __future__ import annotations

import shutil
import sqlite3
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from ..errors import SourceError
from .salvage import _Salvage
from .base import SourceMessage

_HEADER_PAGES = slice(28, 32)  # sqlite file header: the database size in pages


def db3_files(path: Path) -> list[Path]:
    return sorted(path.glob("*.db3")) if path.is_dir() else [path]


def db3_cut_short(path: Path) -> bool:
    """True when the file is shorter than the page count its sqlite header states (a power
    loss cut it): the bag reader would fail midway, so the salvage reader is used instead."""
    try:
        with open(path, "rb") as f:
            head = f.read(100)
    except OSError:
        return False
    if len(head) < 100:
        return True
    page_size = int.from_bytes(head[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    return int.from_bytes(head[_HEADER_PAGES], "big") * page_size > path.stat().st_size


class Ros2DbSalvage(_Salvage):
    """Every readable row of the .db3 file(s) of a ROS 2 bag, without its metadata.yaml."""

    def __init__(self, path: str | Path, *, topics: Iterable[str] | None = None, clock: str = "log",
                 why: str = "") -> None:  # fmt: skip
        p = Path(path)
        self.files = db3_files(p)
        if not self.files:
            raise SourceError(f"{p} is a directory without metadata.yaml or .db3 files, so not a ROS 2 bag.")
        super().__init__(self.files[0], topics=topics, clock=clock, why=why)
        self.name, self.size = str(p), sum(f.stat().st_size for f in self.files)  # the bag, not its first file
        self.note = (f"{p} has no metadata.yaml (the recorder stopped before writing it): read from its "
                     f"database{'s' if len(self.files) > 1 else ''} {', '.join(f.name for f in self.files)}"
                     if p.is_dir() and not (p / "metadata.yaml").is_file() else None)  # fmt: skip

    def __iter__(self) -> Iterator[SourceMessage]:
        with tempfile.TemporaryDirectory(prefix="cclog-db3-") as tmp:
            yield from self._read([_openable(f, Path(tmp)) for f in self.files])

    def _read(self, files: list[Path]) -> Iterator[SourceMessage]:
        store = _typestore(files)  # from the readable copies: a cut file's definitions are still there
        losses: list[str] = []
        rows: list[tuple[int, int, int, int]] = []  # (timestamp, file index, id, topic id)
        topics: list[dict[int, tuple[str, str]]] = []
        for n, f in enumerate(files):
            db = _connect(f)
            topics.append(_topics(db, self.files[n]))
            ids, lost = _readable_rows(db)
            rows += [(t, n, i, tid) for i, tid, t in ids]
            losses += [f"{self.files[n].name}: {what}" for what in lost]
            db.close()
        if not rows and losses:
            raise SourceError(f"{self.name}: no message can be read: {'; '.join(losses)}")
        rows.sort()
        dbs = [_connect(f) for f in files]
        count, last = 0, None
        try:
            for t, n, i, tid in rows:
                topic, msgtype = topics[n].get(tid, ("", ""))
                if self._wanted is not None and topic not in self._wanted:
                    continue
                try:
                    (data,) = dbs[n].execute("SELECT data FROM messages WHERE id = ?", (i,)).fetchone()
                except (sqlite3.DatabaseError, TypeError) as err:
                    losses.append(f"{self.files[n].name}: row {i}: {err}")
                    continue
                try:
                    msg = store.deserialize_cdr(data, msgtype)
                except Exception as err:  # rosbags raises several unrelated types for bad CDR
                    raise SourceError(f"{self.files[n]}: cannot decode the {msgtype or 'unknown'} message row {i} "
                                      f"on {topic or f'topic id {tid}'}: {err}") from err  # fmt: skip
                count, last = count + 1, t
                yield self._message(topic, msgtype, t, msg)
        finally:
            for db in dbs:
                db.close()
        if losses:
            upto = f"the last logged at {last} ns" if last is not None else "none"
            self.lost = (f"{self.name} is damaged ({self.why or 'its database is cut short'}): read {count:,} "
                         f"messages ({upto}); could not be read: {'; '.join(losses)}")  # fmt: skip
        if short := metadata_shortfall(Path(self.name), count, self._wanted):
            self.lost = f"{self.lost}; {short}" if self.lost else f"{self.name} ({self.why}): {short}"


def metadata_shortfall(bag: Path, read: int, wanted: set[str] | None) -> str | None:
    """What the metadata.yaml of the bag directory `bag` (when it has one) counts beyond the
    `read` messages of the `wanted` topics: a listed .db3 file that is missing (the bag reader
    refuses the bag; the others were read without a word, exit 0) or rows lost."""
    from ruamel.yaml import YAML

    try:
        info = YAML(typ="safe").load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        counted = sum(int(t["message_count"]) for t in info["topics_with_message_count"]
                      if wanted is None or t["topic_metadata"]["name"] in wanted)  # fmt: skip
        listed = [Path(f).name for f in info.get("relative_file_paths", [])]
    except (OSError, TypeError, KeyError, ValueError, AttributeError):
        return None  # no metadata.yaml, or one that says nothing usable
    missing = [f for f in listed if not (bag / f).exists()]
    if read >= counted and not missing:
        return None
    gone = f" ({', '.join(missing)}, listed in it, {'is' if len(missing) == 1 else 'are'} missing)" if missing else ""
    return f"metadata.yaml counts {counted:,} messages, its .db3 files hold {read:,}: {max(counted - read, 0):,} missing{gone}"


def _openable(f: Path, tmp: Path) -> Path:
    """`f`, or when it is cut short a copy of its whole pages whose header states that many
    pages: sqlite refuses to prepare any query on a file shorter than its header says."""
    if not db3_cut_short(f):
        return f
    copy = tmp / f.name
    with open(f, "rb") as src, open(copy, "wb") as dst:
        head = src.read(100)
        src.seek(0)
        shutil.copyfileobj(src, dst)
    page_size = int.from_bytes(head[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    pages = f.stat().st_size // page_size
    with open(copy, "r+b") as dst:
        dst.truncate(pages * page_size)
        dst.seek(_HEADER_PAGES.start)
        dst.write(pages.to_bytes(4, "big"))
    return copy


def _connect(f: Path) -> sqlite3.Connection:
    # Read-only and immutable: salvage must not let sqlite roll back or rewrite the damaged file.
    return sqlite3.connect(f"{f.resolve().as_uri()}?mode=ro&immutable=1", uri=True)


def _topics(db: sqlite3.Connection, f: Path) -> dict[int, tuple[str, str]]:
    try:
        return {i: (name, msgtype) for i, name, msgtype in db.execute("SELECT id, name, type FROM topics")}
    except sqlite3.DatabaseError as err:
        raise SourceError(f"{f}: cannot read the topics table of this ROS 2 bag database: {err}") from err


def _readable_rows(db: sqlite3.Connection) -> tuple[list[tuple[int, int, int]], list[str]]:
    """(id, topic id, timestamp) of every message row sqlite can read, and the id ranges it
    cannot: on an error the scan resumes past the failing row, skipping ever further ahead."""
    rows: list[tuple[int, int, int]] = []
    lost: list[str] = []
    after, skip, gap = -1, 1, None  # gap: (first unreadable id, the error)
    while True:
        try:
            for row in db.execute("SELECT id, topic_id, timestamp FROM messages WHERE id > ? ORDER BY id", (after,)):
                if gap is not None:
                    lost.append(f"message rows {gap[0]} to {row[0] - 1} ({gap[1]})")
                    gap = None
                rows.append(row)
                after, skip = row[0], 1
            if gap is not None:
                lost.append(f"message rows from {gap[0]} on ({gap[1]})")
            return rows, lost
        except sqlite3.DatabaseError as err:
            gap = gap or (after + 1, err)
            if skip > 1 << 24:
                lost.append(f"message rows from {gap[0]} on ({gap[1]})")
                return rows, lost
            after, skip = after + skip, skip * 2


def _typestore(files: list[Path]):
    """The type store the bag reader builds (rosbags AnyReader): the bag's own message
    definitions (rosbag2 Iron and later store them in the database), else the latest ROS 2 types."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    typs: dict = {}
    for f in files:
        db = _connect(f)
        try:
            defs = db.execute("SELECT topic_type, encoding, encoded_message_definition FROM message_definitions")
            for msgtype, encoding, text in defs:
                if encoding == "ros2msg" and text:
                    typs.update(get_types_from_msg(text, msgtype))
        except sqlite3.DatabaseError:
            pass  # older bags have no such table (or it is damaged): the latest types stand in
        finally:
            db.close()
    store = get_typestore(Stores.EMPTY if typs else Stores.LATEST)
    store.register(typs)
    return store
