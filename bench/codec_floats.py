"""The columnar codec's float path before and after orjson (issue 14), in one process.

    python3 dev.py bench codec_floats [--rev 5b3c0c8] [--runs 5]

Loads columns.py as it was at --rev (repr rendering and checking) beside today's, swaps
the two functions that differ, and times encode and decode of 200-message windows of real
/odom (every shared MCAP file) and simulated /odom, interleaved, medians. Asserts that both
write the same bytes and decode every text back.
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rev", default="5b3c0c8", help="a commit whose columns.py renders floats with repr")
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    import cclogfs.codecs.columns as cols
    from bench.speed import odometry
    from cclogfs.codecs import raw_size
    from cclogfs.codecs.columnar import ColumnarCodec
    from cclogfs.sim import simulate

    src = subprocess.run(["git", "show", f"{args.rev}:cclogfs/codecs/columns.py"], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout  # fmt: skip
    old = types.ModuleType("cclogfs.codecs.columns_then")
    old.__package__ = "cclogfs.codecs"
    exec(compile(src, f"{args.rev}:columns.py", "exec"), old.__dict__)  # noqa: S102
    paths = {"then": (old._as_floats, old._render_floats), "now": (cols._as_floats, cols._render_floats)}
    data = {"real /odom": odometry(30_000), "simulated /odom": simulate(seed=1, duration_s=300, rate_hz=100).messages}
    for name, msgs in data.items():
        windows = [msgs[i : i + 200] for i in range(0, len(msgs), 200)]
        windows = [([s for s, _ in w], [t for _, t in w]) for w in windows]
        times: dict[str, list[tuple[float, float]]] = {"then": [], "now": []}
        payloads = {}
        for _ in range(args.runs):
            for label, (as_floats, render) in paths.items():
                cols._as_floats, cols._render_floats = as_floats, render
                codec = ColumnarCodec()  # fresh: a codec's shape cache shapes its next window
                t = time.perf_counter()
                enc = [codec.encode(s, texts) for s, texts in windows]
                t1 = time.perf_counter()
                dec = [codec.decode(d, count=len(texts), raw_len=raw_size(s, texts)) for (s, texts), d in zip(windows, enc)]
                t2 = time.perf_counter()
                assert [texts for _, texts in dec] == [texts for _, texts in windows]
                payloads[label] = enc
                times[label].append((t1 - t, t2 - t1))
        assert payloads["then"] == payloads["now"], "the two paths wrote different bytes"
        for label, got in times.items():
            enc_s = statistics.median(e for e, _ in got)
            dec_s = statistics.median(d for _, d in got)
            print(f"{name:18} {label:5} encode {len(msgs) / enc_s:9,.0f} msg/s  decode {len(msgs) / dec_s:9,.0f} msg/s")
    cols._as_floats, cols._render_floats = paths["now"]
    return 0
