"""Aging and retention on real robot logs: size after compaction, worst error, speed.

Usage: python bench/aging.py [--runs 3] [--copies 1]

Builds a keep-all store of nav2_turtlebot.mcap (every topic, 200-message windows, small
segments so retention has something to drop; `--copies` back-to-back copies of the 97 s
run, each shifted by its length: more copies flatter LZMA-6, which finds the repeats), then, for each policy, ages a fresh copy of that store
with `cclogfs.upkeep.compact` and reports: the store's size against the exact store and against
LZMA-6 over the same JSON (both measured in this run), the worst error found by comparing
every float of every kept message with the original (as a fraction of its bound: must be
<= 1), and messages aged per second (median of --runs). Then a budget of half the exact
store: what retention drops. Every aged store must pass fsck --deep.
"""

from __future__ import annotations

import argparse
import json
import lzma
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench._util import SHARED, machine, save_json, topic_messages  # noqa: E402
from cclogfs import open_store  # noqa: E402
from cclogfs.store import check_store  # noqa: E402
from cclogfs.upkeep import Policy, compact, parse_rule  # noqa: E402

NS = 1_000_000_000
TOPICS = ("/odom", "/tf", "/amcl_pose", "/tf_static")
POLICIES = {
    "1e-4": (["1e-4"], None),
    "1e-3": (["1e-3"], None),
    "1e-3, 5 Hz": (["1e-3"], 5.0),
    "1e-2, 1 Hz": (["1e-2"], 1.0),
}


def build_store(path: Path, copies: int) -> tuple[int, int]:
    """The exact store; returns (messages, JSON bytes). LZMA-6 is measured by the caller."""
    per_topic = {t: topic_messages(SHARED / "nav2_turtlebot.mcap", t) for t in TOPICS}
    first = min(s for msgs in per_topic.values() for s, _ in msgs)
    last = max(s for msgs in per_topic.values() for s, _ in msgs)
    span = last - first + NS
    count = size = 0
    with open_store(path, create=True, segment_records=16, sync_every_ms=None) as store:
        for c in range(copies):
            for topic, msgs in per_topic.items():
                if topic == "/tf_static" and c:
                    continue
                shifted = [(s + c * span, t) for s, t in msgs]
                for i in range(0, len(shifted), 200):
                    part = shifted[i : i + 200]
                    store.put_window(topic, part)
                    count += len(part)
                    size += sum(len(t.encode()) for _, t in part)
    return count, size


def floats(value, out):
    if isinstance(value, float):
        out.append(value)
    elif isinstance(value, dict):
        for v in value.values():
            floats(v, out)
    elif isinstance(value, list):
        for v in value:
            floats(v, out)
    return out


def worst_error(exact: Path, aged: Path, bound: float) -> tuple[float, int]:
    """(largest |aged - exact| / bound over every float of every kept message, messages)."""
    worst, checked = 0.0, 0
    with open_store(exact, readonly=True) as a, open_store(aged, readonly=True) as b:
        originals = {w.seq: list(w.messages()) for w in a.query()}
        for w in b.query():
            orig, i = originals[w.seq], 0
            for stamp, text in w.messages():
                # Thinning keeps messages in order: the next original with this stamp.
                while orig[i][0] != stamp:
                    i += 1
                x, y = floats(json.loads(orig[i][1]), []), floats(json.loads(text), [])
                assert len(x) == len(y)
                for u, v in zip(x, y):
                    worst = max(worst, abs(u - v) / bound)
                checked += 1
                i += 1
    return worst, checked


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--copies", type=int, default=1)
    args = parser.parse_args()
    print(machine())
    tmp = Path(tempfile.mkdtemp(prefix="cclog-aging-"))
    try:
        exact = tmp / "exact"
        messages, json_bytes = build_store(exact, args.copies)
        with open_store(exact, readonly=True) as s:
            exact_bytes = s.disk_bytes()
            texts = b"".join(t.encode() for w in s.query() for _, t in w.messages())
        lzma_bytes = len(lzma.compress(texts, preset=6))
        print(f"{messages} messages, JSON {json_bytes / 2**20:.2f} MiB; exact store {exact_bytes / 2**20:.2f} MiB "
              f"({100 * exact_bytes / json_bytes:.2f} % of the JSON); LZMA-6 of the JSON {lzma_bytes / 2**20:.2f} MiB "
              f"({100 * lzma_bytes / json_bytes:.2f} %)")  # fmt: skip
        rows = []
        print(f"{'policy':12} {'store MiB':>9} {'x exact':>8} {'x lzma6':>8} {'% json':>7} {'msgs kept':>9} "
              f"{'worst err/bound':>15} {'msg/s':>8} {'fsck':>5}")  # fmt: skip
        for name, (rules, rate) in POLICIES.items():
            times = []
            for _ in range(args.runs):
                work = tmp / "work"
                shutil.rmtree(work, ignore_errors=True)
                shutil.copytree(exact, work)
                policy = Policy([parse_rule(r) for r in rules], rate)
                t = time.perf_counter()
                with open_store(work) as store:
                    compact(store, policy=policy)
                times.append(time.perf_counter() - t)
            with open_store(work, readonly=True) as s:
                after = s.disk_bytes()
                kept = sum(st["messages"] for st in s.streams().values())
            worst, checked = worst_error(exact, work, policy.rules[-1].bound)
            fsck = check_store(str(work), deep=True)
            row = {"policy": name, "store_bytes": after, "vs_exact": after / exact_bytes,
                   "vs_lzma6": after / lzma_bytes, "pct_json": 100 * after / json_bytes, "messages_kept": kept,
                   "worst_error_over_bound": worst, "messages_checked": checked,
                   "aged_msgs_per_s": messages / statistics.median(times), "fsck_clean": not fsck.errors}  # fmt: skip
            rows.append(row)
            print(f"{name:12} {after / 2**20:9.2f} {row['vs_exact']:8.3f} {row['vs_lzma6']:8.3f} "
                  f"{row['pct_json']:7.2f} {kept:9d} {worst:15.4f} {row['aged_msgs_per_s']:8.0f} "
                  f"{'ok' if row['fsck_clean'] else 'BAD':>5}")  # fmt: skip
        # Retention: half the exact store's size.
        work = tmp / "work"
        shutil.rmtree(work, ignore_errors=True)
        shutil.copytree(exact, work)
        budget = exact_bytes // 2
        with open_store(work) as store:
            report = compact(store, budget=budget)
        dropped = sum(d["windows"] for d in report.dropped.values())
        print(f"budget {budget / 2**20:.2f} MiB: dropped {report.segments_dropped} segments "
              f"({dropped} windows), store {report.disk_after / 2**20:.2f} MiB, "
              f"{'met' if not report.over_budget else 'NOT met'}")  # fmt: skip
        save_json("bench-aging.json", {"machine": machine(), "messages": messages, "json_bytes": json_bytes,
                                       "exact_bytes": exact_bytes, "lzma6_bytes": lzma_bytes, "policies": rows,
                                       "budget": budget, "budget_report": report.to_dict()})  # fmt: skip
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
