"""Odometry-like messages (floats that aging can round, at 10 Hz) and a store of them with
sealed segments, shared by the upkeep tests."""

import json
import math

import cclogfs

NS = 1_000_000_000


def odom(i: int) -> str:
    t = i * 0.1
    return json.dumps({"header": {"stamp": {"sec": i // 10, "nanosec": i % 10 * 100_000_000}, "frame_id": "odom"},
                       "pose": {"x": math.sin(t) * 3.123456789, "y": t * 0.7071067811865476, "n": i},
                       "twist": {"v": 0.25 + 0.01 * math.cos(t), "w": -0.0}})  # fmt: skip


def sealed_store(path, windows=16):
    """/tf_static once, then /odom windows of 5 s at 10 Hz, four windows per segment."""
    store = cclogfs.open_store(path, create=True, segment_records=4, sync_every_ms=None)
    store.put_window("/tf_static", [(0, '{"x": 1.2345678}')])
    for w in range(windows):
        store.put_window("/odom", [(i * NS // 10, odom(i)) for i in range(w * 50, (w + 1) * 50)])
    return store
