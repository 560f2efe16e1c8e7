"""Export windows to a rosbag2 directory (metadata.yaml + one MCAP file), written by rosbags'
own rosbag2 Writer: what `ros2 bag play DIR`, `ros2 bag info DIR` and
`rosbags.highlevel.AnyReader` open as a bag `ros2 bag record` made.

Every stream must be ROS 2 CDR (`export.ros2cdr`): a bag has no JSON channels, so a stream
of unknown type is refused, never left out silently. Messages are rebuilt and serialized as
for the MCAP export (same notes, same errors); the timestamp of each is its stored log
time. Window metadata is not kept (a bag has no place for it; the MCAP export has).

The bag is written in a temporary directory beside DIR and renamed into place when
complete; an existing DIR is replaced only when asked, and only if it is a rosbag2
directory (holds metadata.yaml), so a mistyped path never removes a user's directory.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import InvalidInputError
from .base import Progress, StoredWindow, commit_work_file, remove_stale_work_files
from .mcap import McapStats
from .ros2cdr import AS_JSON_MCAP, Describe, Encode, Ros2Types, message_error, qos, stream_meta


def check_rosbag2_output(path: str | Path, *, force: bool) -> None:
    """Refuse, before any work, a DIR that cannot become a bag (the caller has run the
    common output checks: not an input, --force for an existing one)."""
    path = Path(path)
    if not path.parent.resolve().is_dir():
        raise InvalidInputError(f"Output {path}: directory {path.parent.resolve()} does not exist.")
    if force and os.path.lexists(path) and not (path.is_dir() and (path / "metadata.yaml").is_file()):
        raise InvalidInputError(f"Output {path} exists and is not a rosbag2 directory (no metadata.yaml); "
                                "--force replaces only a bag: choose another output.")  # fmt: skip


def export_rosbag2(
    windows: Iterable[StoredWindow], path: str | Path, *, replace: bool = False, progress: Progress | None = None,
    describe: Describe | None = None,
) -> McapStats:  # fmt: skip
    """Write every window's messages as a rosbag2 bag in directory `path` (`describe` as
    for export_mcap)."""
    path = Path(path)
    check_rosbag2_output(path, force=replace)
    if os.path.lexists(path) and not replace:
        raise InvalidInputError(f"Output {path} exists; pass --force to replace it, or choose another output.")
    stats = McapStats(files=[str(path)])
    ros2 = Ros2Types()
    remove_stale_work_files(path)  # a killed export's work directory (its name holds the pid)
    work = Path(tempfile.mkdtemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp", dir=path.parent))
    try:
        _write(windows, work / path.name, ros2, stats, progress, describe)
        if os.path.lexists(path):
            os.replace(path, work / "replaced")
        commit_work_file(work / path.name, path)  # synced: a power cut leaves no partial bag
    finally:
        shutil.rmtree(work, ignore_errors=True)
    stats.notes = ros2.notes
    stats.files = [str(p) for p in sorted(path.iterdir())]
    return stats


def _write(windows: Iterable[StoredWindow], bag: Path, ros2: Ros2Types, stats: McapStats,
           progress: Progress | None, describe: Describe | None) -> None:  # fmt: skip
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)  # zstd chunks, as rosbag2's MCAP plugin
    writer.open()
    try:
        streams: dict[str, tuple[Any, Encode]] = {}
        counts: dict[str, int] = {}
        for w in windows:
            if w.name not in streams:
                streams[w.name] = _connect(writer, ros2, w, *stream_meta(ros2, w, describe))
            conn, encode = streams[w.name]
            before = counts.get(w.name, 0)
            index = before
            for stamp_ns, text in w.messages():
                if stamp_ns < 0:
                    raise InvalidInputError(f"The message on {w.name} at {stamp_ns} ns cannot go into a rosbag2 "
                                            "bag, whose times are unsigned; export a range after 0 (--start 0).")  # fmt: skip
                try:
                    data = encode(text)
                except InvalidInputError as err:
                    raise message_error(w.name, index, stamp_ns, w.seq, err, as_json=AS_JSON_MCAP) from None
                writer.write(conn, stamp_ns, data)
                index += 1
            counts[w.name] = index
            stats.wrote(w, index - before)
            if progress is not None:
                progress(index - before)
    except BaseException:
        writer.abort()  # the caller removes the temporary bag whole
        raise
    writer.close()


def _connect(writer: Any, ros2: Ros2Types, w: StoredWindow, meta: Mapping[str, Any],
             why: str | None) -> tuple[Any, Encode]:  # fmt: skip
    msgtype = str(meta.get("msgtype") or "")
    if why:
        raise InvalidInputError(f"{w.name} cannot go into a rosbag2 bag: {why}; leave it out with --topic, "
                                "or export to --mcap, which writes it as JSON.")  # fmt: skip
    name = ros2.schema(msgtype)[0]
    conn = writer.add_connection(w.name, name, typestore=ros2.typestore, offered_qos_profiles=[qos(w.name, meta)])
    return conn, ros2.encoder(w.name, msgtype)
