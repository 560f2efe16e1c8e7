"""Columnar codec against LZMA-6 on real topics: size, encode and decode speed.

Usage: python bench/codec_columnar.py [--runs 5] [--window 200]
Sizes are of 200-message windows (each encoded alone) summed over the whole topic, and of
the first window alone; LZMA-6 runs over the same JSON texts in the same process.
"""

from __future__ import annotations

import argparse
import lzma
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench._util import load_topic, median_time  # noqa: E402
from cclogfs.codecs import codec_from_config, raw_size  # noqa: E402

TOPICS = [
    ("nav2_turtlebot.mcap", "/odom"),
    ("nav2_turtlebot.mcap", "/tf"),
    ("nav2_turtlebot.mcap", "/amcl_pose"),
    ("tf_example.bag", "/tf"),
]


def bench_topic(file: str, topic: str, window: int, runs: int) -> dict:
    messages = load_topic(file, topic)
    windows = [messages[i : i + window] for i in range(0, len(messages), window)]
    windows = [([s for s, _ in w], [t for _, t in w]) for w in windows]
    codec = codec_from_config("columnar")
    json_bytes = sum(len(t) for _, texts in windows for t in texts)

    encoded = [codec.encode(s, t) for s, t in windows]
    for (s, t), data in zip(windows, encoded):  # the benchmark only counts exact round trips
        assert codec.decode(data, count=len(t), raw_len=raw_size(s, t)) == (s, t)
    lz = [lzma.compress(b"".join(t), preset=6) for _, t in windows]
    whole_lz = len(lzma.compress(b"".join(t for _, ts in windows for t in ts), preset=6))

    enc_s = median_time(lambda: [codec.encode(s, t) for s, t in windows], runs)
    lz_s = median_time(lambda: [lzma.compress(b"".join(t), preset=6) for _, t in windows], runs)
    dec_s = median_time(
        lambda: [
            codec.decode(d, count=len(t), raw_len=raw_size(s, t))
            for (s, t), d in zip(windows, encoded)
        ],
        runs,
    )
    col, lzs = sum(map(len, encoded)), sum(map(len, lz))
    return {
        "file": file,
        "topic": topic,
        "messages": len(messages),
        "json_bytes": json_bytes,
        "columnar_bytes": col,
        "lzma6_window_bytes": lzs,
        "lzma6_whole_bytes": whole_lz,
        "ratio_vs_lzma6_windows": col / lzs,
        "ratio_vs_lzma6_whole": col / whole_lz,
        "first_window_ratio": len(encoded[0]) / len(lz[0]),
        "columnar_pct_of_json": 100 * col / json_bytes,
        "encode_speedup_vs_lzma6": lz_s / enc_s,
        "encode_msgs_per_s": len(messages) / enc_s,
        "decode_msgs_per_s": len(messages) / dec_s,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--window", type=int, default=200)
    args = parser.parse_args()
    head = (
        f"{'file':20} {'topic':11} {'msgs':>5} {'%json':>6} {'vs lzma win':>11} "
        f"{'vs lzma all':>11} {'1st win':>7} {'enc x lzma':>10} {'enc msg/s':>10} {'dec msg/s':>10}"
    )
    print(f"columnar vs LZMA-6, {args.window}-message windows, medians of {args.runs} runs")
    print(head)
    for file, topic in TOPICS:
        r = bench_topic(file, topic, args.window, args.runs)
        print(
            f"{file:20} {topic:11} {r['messages']:5d} {r['columnar_pct_of_json']:6.2f} "
            f"{r['ratio_vs_lzma6_windows']:11.3f} {r['ratio_vs_lzma6_whole']:11.3f} "
            f"{r['first_window_ratio']:7.3f} {r['encode_speedup_vs_lzma6']:10.1f} "
            f"{r['encode_msgs_per_s']:10.0f} {r['decode_msgs_per_s']:10.0f}"
        )


if __name__ == "__main__":
    main()
