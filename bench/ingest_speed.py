#!/usr/bin/env python3
"""Ingest speed: messages per second from a bag and from JSON Lines, medians of N runs.

    python -m bench ingest_speed [--runs 5] [--jsonl-copies 6]   (or python bench/ingest_speed.py)

Measured on ../shared/data/nav2_turtlebot.mcap (8,197 messages, all topics). Each figure
is printed beside a baseline measured in the same run, so the ratio holds on any machine:
  bag:   rosbags read+deserialize only; jsontext.ros.message_to_json (uncached) conversion
  jsonl: a bare `json.loads` per line; json.loads + re-dumping msg (what slicing avoids)
"pipeline" adds the ingest side of recording: JSONL written out (convert), or windows of
100 messages put into a store and synced (the classifier is not included).
Targets: 20,000 msg/s from a bag, 100,000 msg/s from JSONL.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from rosbags.highlevel import AnyReader  # noqa: E402

from cclogfs.ingest import format_line, open_source  # noqa: E402
from cclogfs.jsontext.ros import message_stamp_ns, message_to_json  # noqa: E402

BAG = ROOT.parent / "shared" / "data" / "nav2_turtlebot.mcap"


def rate(fn, runs: int) -> float:
    """Median messages/s of `fn()`, which returns the number of messages it handled."""
    rates = []
    for _ in range(runs):
        t0 = time.perf_counter()
        n = fn()
        rates.append(n / (time.perf_counter() - t0))
    return statistics.median(rates)


def bag_deserialize_only() -> int:
    n = 0
    with AnyReader([BAG]) as reader:
        for con, _, raw in reader.messages():
            reader.deserialize(raw, con.msgtype)
            n += 1
    return n


def bag_rosjson_uncached() -> int:
    n = 0
    with AnyReader([BAG]) as reader:
        for con, logtime, raw in reader.messages():
            msg = reader.deserialize(raw, con.msgtype)
            message_to_json(msg), message_stamp_ns(msg) or logtime
            n += 1
    return n


def read_all(path) -> int:
    with open_source(path) as src:
        return sum(1 for _ in src)


def convert(path, out: Path) -> int:
    n = 0
    with open_source(path) as src, open(out, "w", encoding="utf-8") as f:
        for m in src:
            f.write(format_line(m.topic, m.stamp_ns, m.text))
            n += 1
    return n


def to_store(path, store_dir: Path) -> int:
    import shutil

    import cclogfs

    shutil.rmtree(store_dir, ignore_errors=True)
    n = 0
    buffers: dict[str, list[tuple[int, str]]] = {}
    with cclogfs.open_store(store_dir, create=True) as store, open_source(path) as src:
        for m in src:
            buf = buffers.setdefault(m.topic, [])
            buf.append((m.stamp_ns, m.text))
            if len(buf) == 100:
                store.put_window(m.topic, buf)
                buffers[m.topic] = []
            n += 1
        for topic, buf in buffers.items():
            if buf:
                store.put_window(topic, buf)
        store.sync()
    return n


def jsonl_loads_only(path: Path) -> int:
    n = 0
    with open(path, "rb") as f:
        for line in f:
            json.loads(line)
            n += 1
    return n


def jsonl_redump(path: Path) -> int:
    n = 0
    with open(path, "rb") as f:
        for line in f:
            obj = json.loads(line)
            obj["topic"], obj["stamp_ns"], json.dumps(obj["msg"])
            n += 1
    return n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--jsonl-copies", type=int, default=6, help="copies of the bag in the JSONL file")
    args = ap.parse_args()
    if not BAG.exists():
        print(f"{BAG} is missing", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        tmpdir = Path(tmp)
        once = tmpdir / "once.jsonl"
        convert(BAG, once)
        jsonl = tmpdir / "big.jsonl"
        with open_source(once) as src:
            msgs = list(src)
        with open(jsonl, "w", encoding="utf-8") as f:
            for k in range(args.jsonl_copies):  # each copy 200 s later: times keep rising
                for m in msgs:
                    f.write(format_line(m.topic, m.stamp_ns + k * 200 * 10**9, m.text))
        lines = sum(1 for _ in open(jsonl, "rb"))
        mib = jsonl.stat().st_size / 2**20
        r = args.runs
        rows = [
            ("bag", "rosbags read + deserialize only (baseline)", rate(bag_deserialize_only, r)),
            ("bag", "read + jsontext.ros.message_to_json uncached", rate(bag_rosjson_uncached, r)),
            ("bag", "RosbagSource (read + JSON text)", rate(lambda: read_all(BAG), r)),
            ("bag", "pipeline: convert to JSONL file", rate(lambda: convert(BAG, tmpdir / "o.jsonl"), r)),
            ("bag", "pipeline: into a store, 100-msg windows", rate(lambda: to_store(BAG, tmpdir / "s1"), r)),
            ("jsonl", "json.loads per line only (baseline)", rate(lambda: jsonl_loads_only(jsonl), r)),
            ("jsonl", "json.loads + re-dump msg", rate(lambda: jsonl_redump(jsonl), r)),
            ("jsonl", "JsonlSource (validated, byte-exact)", rate(lambda: read_all(jsonl), r)),
            ("jsonl", "pipeline: convert to JSONL file", rate(lambda: convert(jsonl, tmpdir / "o.jsonl"), r)),
            ("jsonl", "pipeline: into a store, 100-msg windows", rate(lambda: to_store(jsonl, tmpdir / "s2"), r)),
        ]
    print(f"bag: {BAG.name}, 8,197 messages; jsonl: {lines:,} lines, {mib:.1f} MiB; median of {r} runs")
    base = {"bag": rows[0][2], "jsonl": rows[5][2]}
    target = {"bag": 20_000, "jsonl": 100_000}
    for kind, label, value in rows:
        print(
            f"{kind:5} {label:42} {value:10,.0f} msg/s  x{value / base[kind]:.2f} of baseline"
            f"  ({value / target[kind]:.2f} of target)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
