"""Export windows to Hive-partitioned Parquet for SQL engines (DuckDB, Spark, pandas).

Layout: `DIR/robot=NAME/stream=STREAM/date=YYYY-MM-DD/part-NNNNN.parquet`, the stream
name percent-encoded ("/odom" -> "%2Fodom", which DuckDB and pyarrow decode back) and
the date the UTC day of the message stamp. Columns: `stamp_ns`, `window_seq`, one typed
column per message field with nested objects flattened to dotted names
(`pose.pose.position.x`), arrays as list columns, and `json`, the exact stored text.
"""

from __future__ import annotations

import datetime as dt
import errno
import json
import os
import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Any
from urllib.parse import quote

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from ..errors import InvalidInputError
from .base import ExportStats, Progress, StoredWindow, remove_stale_work_files

# Names the export itself uses; a top-level message field with one of them is "msg.NAME".
RESERVED = frozenset({"stamp_ns", "window_seq", "json", "robot", "stream", "date"})
_DAY_NS = 86_400_000_000_000
_EPOCH = dt.date(1970, 1, 1)


def flatten(
    obj: dict[str, Any], prefix: str = "", out: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Nested objects as one level with dotted keys; lists and scalars are leaves."""
    if out is None:
        out = {}
    for key, value in obj.items():
        name = prefix + key
        if not prefix and name in RESERVED:
            name = "msg." + name
        while name in out:  # {"a.b": 1, "a": {"b": 2}}: keep both, the later one renamed
            name += "~"
        if type(value) is dict:
            if value:
                flatten(value, name + ".", out)
            else:
                out[name] = None  # an empty object has no columns; the json column keeps it
        else:
            out[name] = value
    return out


class _Stream:
    """Rows of one stream waiting to be written, and the column types it settled on."""

    def __init__(self) -> None:
        self.stamps: list[int] = []
        self.seqs: list[int] = []
        self.texts: list[str] = []
        self.rows: list[dict[str, Any]] = []
        self.schema: pa.Schema | None = None
        self.parts = 0


def export_parquet(
    windows: Iterable[StoredWindow],
    out_dir: str | Path,
    *,
    robot: str,
    rows_per_part: int = 100_000,
    replace: bool = False,
    progress: Progress | None = None,
) -> ExportStats:
    """Write every window's messages under `out_dir/robot=ROBOT/`."""
    if not robot or any(c in robot for c in "/\\=") or robot in (".", ".."):
        raise InvalidInputError(
            f"Robot name {robot!r} cannot be a partition value: use a non-empty name "
            "without '/', '\\' or '='."
        )
    root = Path(out_dir) / f"robot={quote(robot, safe='')}"
    if root.exists() and not replace:
        raise InvalidInputError(
            f"{root} already holds an export for robot {robot!r}; remove it, pass "
            "replace=True (--force), or choose another directory."
        )
    # Written beside its place and renamed in when whole, as the file exports are: a failed
    # export (a stream name too long for a directory, a damaged window, Ctrl-C) left the
    # partitions written so far, a partial data set, and with --force had deleted the old
    # one first. The dot keeps the work hidden from Hive readers (Spark, `**/*.parquet`).
    remove_stale_work_files(root)  # a killed export's `.partial-PID` (and `.old-PID`)
    work = root.with_name(f".{root.name}.partial-{os.getpid()}")
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    try:
        stats = _write_streams(windows, work, rows_per_part, progress)
        _swap_in(work, root)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    stats.files = [str(root / Path(f).relative_to(work)) for f in stats.files]
    return stats


def _swap_in(work: Path, root: Path) -> None:
    """Put the finished export `work` in the place of `root` (an older export, or none)."""
    if not root.exists():
        work.rename(root)
        return
    old = root.with_name(f".{root.name}.old-{os.getpid()}")
    shutil.rmtree(old, ignore_errors=True)
    root.rename(old)
    work.rename(root)
    shutil.rmtree(old)


def _write_streams(windows: Iterable[StoredWindow], root: Path, rows_per_part: int,
                   progress: Progress | None) -> ExportStats:  # fmt: skip
    """Every window's messages as parts under `root`."""
    stats = ExportStats()
    streams: dict[str, _Stream] = {}
    for w in windows:
        buf = streams.get(w.name)
        if buf is None:
            buf = streams[w.name] = _Stream()
        count = 0
        for stamp_ns, text in w.messages():
            buf.stamps.append(stamp_ns)
            buf.seqs.append(w.seq)
            buf.texts.append(text)
            buf.rows.append(flatten(json.loads(text)))
            count += 1
        stats.wrote(w, count)
        if progress is not None:
            progress(count)
        if len(buf.rows) >= rows_per_part:
            _flush(root, w.name, buf, stats)
    for name, buf in streams.items():
        _flush(root, name, buf, stats)
    return stats


def _flush(root: Path, name: str, buf: _Stream, stats: ExportStats) -> None:
    if not buf.rows:
        return
    table = _conform(_table(buf), buf.schema)
    if buf.schema is None:
        buf.schema = table.schema
    days = pa.array([s // _DAY_NS for s in buf.stamps], pa.int64())
    stream_dir = root / f"stream={quote(name, safe='')}"
    for day in sorted(set(days.to_pylist())):
        part = table.filter(pc.equal(days, day))
        date = (_EPOCH + dt.timedelta(days=day)).isoformat()
        out = stream_dir / f"date={date}" / f"part-{buf.parts:05d}.parquet"
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            if err.errno != errno.ENAMETOOLONG:
                raise
            shown = repr(name) if len(name) <= 80 else f"{name[:60]!r}..."
            raise InvalidInputError(f"Stream {shown} cannot be a Parquet partition: its directory name "
                                    f"{stream_dir.name[:40]}... is too long for the file system; leave it out "
                                    "with --topic.") from None  # fmt: skip
        pq.write_table(part, out, compression="zstd")
        stats.files.append(str(out))
    buf.parts += 1
    buf.stamps, buf.seqs, buf.texts, buf.rows = [], [], [], []


def _table(buf: _Stream) -> pa.Table:
    names: dict[str, None] = {}
    for row in buf.rows:
        names.update(dict.fromkeys(row))
    columns: dict[str, pa.Array] = {
        "stamp_ns": pa.array(buf.stamps, pa.int64()),
        "window_seq": pa.array(buf.seqs, pa.int64()),
    }
    for name in names:
        columns[name] = _column([row.get(name) for row in buf.rows])
    columns["json"] = pa.array(buf.texts, pa.string())
    return pa.table(columns)


def _column(values: list[Any]) -> pa.Array:
    """A typed column; values pyarrow cannot type together (str and number...) as JSON text."""
    try:
        return pa.array(values)
    except (pa.ArrowInvalid, pa.ArrowTypeError, OverflowError):
        return pa.array([None if v is None else json.dumps(v) for v in values], pa.string())


def _conform(table: pa.Table, schema: pa.Schema | None) -> pa.Table:
    """Cast columns to the types earlier parts of the stream used, where they convert."""
    if schema is None:
        return table
    for i, field in enumerate(table.schema):
        j = schema.get_field_index(field.name)
        if j < 0 or schema.field(j).type == field.type:
            continue
        try:
            table = table.set_column(i, field.name, table.column(i).cast(schema.field(j).type))
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError):
            pass  # keep this part's own type; readers with union_by_name still see both
    return table
