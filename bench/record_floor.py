"""Where `cclog record` of JSONL spends each message, stage by stage (issue 14).

    python3 dev.py bench record_floor [--lines 60000] [--rounds 5]

Input: the first --lines lines of `bench speed`'s odometry JSONL (made by `python3 dev.py
bench speed` in out/). Every stage runs in this process on the same lines, interleaved
over --rounds rounds; each figure is the smallest CPU time (process_time) per message,
the steadiest figure on a shared machine. Stages:

- `orjson.loads` per line: the issue's floor (the target is 0.4x its rate);
- the source's parts: reading lines, simdjson over each line (the validation alone),
  the whole JsonlSource (read, match, validate, decode, one message object each), with
  the compiled splitter (cclogfs/ingest/_jsonl_split.c) when built and without it;
- the pipeline's loop (checks, counts, the KeepAll window policy), a message at a time
  and a list at a time (what `record` does with a JSONL source);
- the store's per-message checks of a window (`encode_messages`);
- the columnar encoder per window, whole and its value-row step alone, with the
  compiled row finder (cclogfs/codecs/_rows.c) when built and with the re module;
- `record` itself (the CLI's `main`, in this process, after imports).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import itertools
import shutil
import tempfile
import time
from pathlib import Path

from ._util import OUT


def _stages(path: Path, lines: list[bytes]) -> tuple[dict, Path]:
    import orjson
    import simdjson
    import zstandard

    from cclogfs.cli import main as cclog
    from cclogfs.codecs import shapes
    from cclogfs.codecs.columnar_encode import encode_window
    from cclogfs.ingest import jsonl
    from cclogfs.ingest.jsonl import JsonlSource
    from cclogfs.pipeline import KeepAll, RecordStats, check_message
    from cclogfs.store.check import encode_messages

    part = path.parent / f"floor-{len(lines)}.jsonl"
    part.write_bytes(b"".join(lines))
    with JsonlSource(part) as source:
        msgs = list(source)
    policy, windows = KeepAll(), []
    for m in msgs:
        windows += policy.push(m.topic, m.stamp_ns, m.text)
    windows += policy.flush()
    compiled = getattr(shapes, "_match_rows_c", None)  # None before the helper existed
    compiled_columns = getattr(shapes, "_match_columns_c", None)  # None before it gave columns

    def each_line(fn):
        def run():
            for line in lines:  # results dropped at once, as the speed bench's anchor does
                fn(line)
        return run

    def read_lines():
        with open(part, "rb") as f:
            for _ in f:
                pass

    splitter = getattr(jsonl, "_split_lines_c", None)  # None before the compiled splitter existed

    def source(split_lines):
        def run():
            jsonl._split_lines_c = split_lines
            try:
                with JsonlSource(part) as s:
                    for _ in s:
                        pass
            finally:
                jsonl._split_lines_c = splitter
        return run

    def pipeline_loop():
        stats, keep = RecordStats(), KeepAll()
        for m in msgs:
            check_message(m.topic, m.stamp_ns, m.text, check_json=False)
            stats.saw(m.topic, m.text)
            keep.push(m.topic, m.stamp_ns, m.text)

    batches = [msgs[i : i + 64] for i in range(0, len(msgs), 64)]  # about what a 64 KiB read holds

    def pipeline_lists():  # pipeline._record_batches without the store
        from cclogfs.pipeline import first_bad_text

        stats, keep = RecordStats(), KeepAll()
        for batch in batches:
            texts = [m.text for m in batch]
            first_bad_text(texts, check_json=False)
            stats.saw_many([m.topic for m in batch], texts)
            keep.push_many(batch)

    def encode(row_finder):
        def run():
            shapes._match_rows_c = row_finder
            shapes._match_columns_c = row_finder and compiled_columns
            try:
                matcher, z = shapes.ShapeMatcher(), zstandard.ZstdCompressor(level=3)
                for w in windows:
                    encode_window(z, matcher, 4, [s for s, _ in w.messages], [t for _, t in w.messages])
            finally:
                shapes._match_rows_c, shapes._match_columns_c = compiled, compiled_columns
        return run

    def rows(row_finder):
        def run():
            shapes._match_rows_c = row_finder
            shapes._match_columns_c = row_finder and compiled_columns
            try:
                matcher = shapes.ShapeMatcher()
                for w in windows:
                    matcher.group_window([t for _, t in w.messages])
            finally:
                shapes._match_rows_c, shapes._match_columns_c = compiled, compiled_columns
        return run

    def record():
        tmp = tempfile.mkdtemp(dir=OUT)
        try:
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                cclog(["record", str(part), "--store", f"{tmp}/s"])
        finally:
            shutil.rmtree(tmp)

    parser = simdjson.Parser()
    stages = {
        "orjson.loads per line (the floor)": each_line(orjson.loads),
        "read lines": read_lines,
        "simdjson parse of each line": each_line(parser.parse),
        "JsonlSource, whole": source(splitter),
        "JsonlSource, Python splitter": source(None) if splitter else None,
        "pipeline loop per message (KeepAll)": pipeline_loop,
        "pipeline loop, a list at a time (KeepAll)": pipeline_lists if hasattr(KeepAll, "push_many") else None,
        "store checks per message (encode_messages)": lambda: [encode_messages(w.messages, check_json=False) for w in windows],
        "columnar encode, compiled row finder": encode(compiled) if compiled else None,
        "columnar encode, re module": encode(None),
        "  value rows alone, compiled": rows(compiled) if compiled else None,
        "  value rows alone, re module": rows(None),
        "record, in-process after imports": record,
    }  # fmt: skip
    return {k: v for k, v in stages.items() if v is not None}, part


def speed_lines(n: int) -> tuple[Path, list[bytes]]:
    """The first n lines of the odometry JSONL that `bench speed` makes in out/."""
    found = sorted(OUT.glob("speed-data-*/odom.jsonl"))
    if not found:
        raise SystemExit("no odometry JSONL in out/: run `python3 dev.py bench speed` first")
    with open(found[0], "rb") as f:
        return found[0], list(itertools.islice(f, n))


def smallest_cpu(stages: dict, rounds: int) -> dict[str, float]:
    """Each stage's smallest CPU seconds over `rounds` rounds, every stage once a round."""
    best = {k: float("inf") for k in stages}
    for _ in range(rounds):
        for name, fn in stages.items():
            t = time.process_time()
            fn()
            best[name] = min(best[name], time.process_time() - t)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lines", type=int, default=60_000)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    path, lines = speed_lines(args.lines)
    stages, part = _stages(path, lines)
    try:
        best = smallest_cpu(stages, args.rounds)
    finally:
        part.unlink()
    floor = best["orjson.loads per line (the floor)"]
    print(f"{args.lines:,} lines of {path}, smallest CPU time of {args.rounds} interleaved rounds")
    print(f"{'stage':<46} {'us/msg':>7} {'x floor':>8}")
    for name, secs in best.items():
        print(f"{name:<46} {1e6 * secs / args.lines:7.2f} {secs / floor:8.2f}")
    rate = args.lines / best["record, in-process after imports"]
    print(f"record: {rate:,.0f} msg/s, {floor / best['record, in-process after imports']:.2f}x the orjson floor's rate")
    return 0
