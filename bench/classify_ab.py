"""The columnar encoder's `classify`, an older columns.py against today's, in one process.

    python3 dev.py bench classify_ab [--rev 9c7a0a8] [--messages 60000] [--rounds 15]

Encodes 200-message windows of real /odom (every shared MCAP file's, as the speed bench
takes them) once, collecting the value columns that `classify` and `classify_joined` see
(a number slot's tokens joined by ",", from the eighth pass); checks that columns.py at
--rev and today's give every column the same kind and values; then times the check of
all the columns, and of the FLOAT ones, the two versions in alternating rounds: --rev's
`classify` of each column's tokens (what its row finder gave), today's as the encoder
calls it. Prints CPU microseconds a message (minimum over rounds) and the median and range
of the pair ratios (issue 14, sixth and eighth passes).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def load_columns(rev: str) -> types.ModuleType:
    """cclogfs/codecs/columns.py as it was at rev, as a module beside today's."""
    src = subprocess.run(["git", "show", f"{rev}:cclogfs/codecs/columns.py"], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout  # fmt: skip
    old = types.ModuleType("cclogfs.codecs.columns_then")
    old.__package__ = "cclogfs.codecs"
    exec(compile(src, f"{rev}:columns.py", "exec"), old.__dict__)  # noqa: S102
    return old


def same(a, b) -> bool:
    """Whether two classify results are the same kind and values."""
    import numpy as np

    (ka, va), (kb, vb) = a, b
    if ka != kb:
        return False
    if isinstance(va, tuple):  # DECIMAL: (digits, values)
        return va[0] == vb[0] and va[1].tobytes() == vb[1].tobytes()
    if isinstance(va, np.ndarray):
        return va.tobytes() == vb.tobytes()
    return va == vb


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rev", default="9c7a0a8", help="the commit whose columns.py is the baseline")
    ap.add_argument("--messages", type=int, default=60_000)
    ap.add_argument("--rounds", type=int, default=15)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    import cclogfs.codecs.columnar_encode as encode
    import cclogfs.codecs.columns as now
    from bench.speed import odometry
    from cclogfs.codecs.columnar import ColumnarCodec
    from cclogfs.codecs.columnar_format import ColumnKind
    from cclogfs.codecs.shapes import column_tokens

    then = load_columns(args.rev)
    msgs = odometry(args.messages)
    columns: list[tuple] = []  # (what today's encoder checks, its count, decimal)
    classify, joined = encode.classify, encode.classify_joined
    encode.classify = lambda tokens, decimal=False: (columns.append((tokens, len(tokens), decimal)), classify(tokens, decimal))[1]
    encode.classify_joined = lambda text, n, decimal=False: (columns.append((text, n, decimal)), joined(text, n, decimal))[1]
    codec = ColumnarCodec()
    for i in range(0, len(msgs), 200):
        codec.encode([s for s, _ in msgs[i : i + 200]], [t for _, t in msgs[i : i + 200]])
    encode.classify, encode.classify_joined = classify, joined
    tokens_of = [tuple(column_tokens(column, n)) for column, n, _ in columns]  # what --rev's row finder gave

    def today(column, n, decimal):
        return now.classify_joined(column, n, decimal) if isinstance(column, str) else now.classify(column, decimal)

    for (column, n, decimal), tokens in zip(columns, tokens_of):
        assert same(then.classify(tokens, decimal), today(column, n, decimal)), tokens[:3]
    floats = [k for k, c in enumerate(columns) if today(*c)[0] is ColumnKind.FLOAT]

    def run(module, chosen) -> float:
        start = time.process_time()
        if module is then:
            for k in chosen:
                then.classify(tokens_of[k], columns[k][2])
        else:
            for k in chosen:
                today(*columns[k])
        return (time.process_time() - start) / len(msgs) * 1e6

    print(f"{len(msgs):,} messages, {len(columns):,} columns ({len(floats):,} FLOAT); {args.rev} against today's")
    for label, chosen in (("all columns", range(len(columns))), ("FLOAT columns", floats)):
        a, b = [], []
        for _ in range(args.rounds):
            a.append(run(then, chosen))
            b.append(run(now, chosen))
        ratios = [y / x for x, y in zip(a, b)]
        print(f"classify, {label:13}: {min(a):.3f} -> {min(b):.3f} us a message (minimum); pair ratios "
              f"median {statistics.median(ratios):.3f} ({min(ratios):.2f}-{max(ratios):.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
