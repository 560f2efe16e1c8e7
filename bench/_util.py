"""Helpers shared by the benchmarks: the machine note, medians, the real data."""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path

SHARED = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
DATA = SHARED  # the name the codec benchmarks use
OUT = Path(__file__).resolve().parent.parent / "out"


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, {platform.system()}"


def median_time(fn, runs: int = 5) -> float:
    """Median wall time of `fn()` over `runs` calls (the machine is shared and noisy)."""
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def topic_messages(path: Path, topic: str, *, stamp: str = "header") -> list[tuple[int, str]]:
    """(stamp_ns, rosbridge JSON) of one topic of a bag, the way cclogfs converts it; the
    stamp is header.stamp (the log time when there is none), or the log time (stamp="log")."""
    from rosbags.highlevel import AnyReader

    from cclogfs.jsontext.ros import MessageConverter, message_stamp_ns

    to_json = MessageConverter().to_json
    out = []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for con, logtime, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, con.msgtype)
            header = message_stamp_ns(msg) if stamp == "header" else None
            out.append((logtime if header is None else header, to_json(msg)))
    return out


def load_topic(file: str, topic: str) -> list[tuple[int, str]]:
    """(log time ns, rosbridge JSON text) of every message of one topic of a shared file:
    str, as the codecs take texts."""
    return topic_messages(SHARED / file, topic, stamp="log")


def odom_messages() -> list[tuple[int, str]]:
    """/odom of nav2_turtlebot.mcap, or a synthetic stand-in when ../shared is absent."""
    path = SHARED / "nav2_turtlebot.mcap"
    if path.exists():
        return topic_messages(path, "/odom")
    return [(i * 37_000_000, json.dumps({"x": i * 0.01, "y": 0.0, "i": i})) for i in range(2000)]


def save_json(name: str, data: dict) -> Path:
    OUT.mkdir(exist_ok=True)
    path = OUT / name
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path


def peak_rss_mib() -> float:
    """This process's peak resident memory (VmHWM). Not ru_maxrss: Linux keeps that across
    execve, so a child started from a big benchmark process would report its parent's peak."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


class BytesFile:
    """Bytes in memory read as one open file (the descriptor is ignored): what the store's
    streamed searches (`records.intact_in`) need of a FileSystem, for damage loops that
    would otherwise write a file per case."""

    def __init__(self, data: bytes):
        self.data = data

    def pread(self, _fd: int, n: int, offset: int) -> bytes:
        return self.data[offset : offset + n]

    def next_data(self, _fd: int, offset: int) -> int:
        return offset  # no holes in memory

    def size(self, _fd: int) -> int:
        return len(self.data)
