"""Helpers shared by the benchmarks: the machine note, medians, the real data."""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path

SHARED = Path(__file__).resolve().parent.parent.parent / "shared" / "data"
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


def topic_messages(path: Path, topic: str) -> list[tuple[int, str]]:
    """(stamp_ns, rosbridge JSON) of one topic of a bag, the way cclogfs converts it."""
    from rosbags.highlevel import AnyReader

    from cclogfs.rosjson import message_stamp_ns, message_to_json

    out = []
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for con, logtime, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, con.msgtype)
            stamp = message_stamp_ns(msg)
            out.append((logtime if stamp is None else stamp, message_to_json(msg)))
    return out


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
