"""Shared helpers of the benchmarks: load real topics as rosbridge JSON, time things."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data"


def load_topic(file: str, topic: str) -> list[tuple[int, bytes]]:
    """(log time ns, rosbridge JSON bytes) of every message of one topic."""
    from rosbags.highlevel import AnyReader

    from cclogfs.rosjson import message_to_json

    with AnyReader([DATA / file]) as reader:
        cons = [c for c in reader.connections if c.topic == topic]
        return [
            (stamp, message_to_json(reader.deserialize(raw, con.msgtype)).encode())
            for con, stamp, raw in reader.messages(connections=cons)
        ]


def median_time(fn: Callable[[], object], runs: int) -> float:
    """Median wall time of fn over runs calls, in seconds."""
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)
