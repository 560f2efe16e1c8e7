"""Columnar codec against LZMA-6 on real topics: size, encode and decode speed.

Usage: python bench/codec_columnar.py [--runs 5] [--window 200]
       python bench/codec_columnar.py --aged 3 4     # sizes of aged (rounded) data only
Sizes are of 200-message windows (each encoded alone) summed over the whole topic, and of
the first window alone; LZMA-6 runs over the same JSON texts in the same process.
With --aged D..., every float token is first rounded to D digits after the point (as the
aging tool writes it) and the sizes of format versions 3 and 4 are compared.
"""

from __future__ import annotations

import argparse
import decimal
import lzma
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench._util import load_topic, median_time  # noqa: E402
from cclogfs.codecs import codec_from_config, raw_size  # noqa: E402
from cclogfs.codecs.columnar import ColumnarCodec  # noqa: E402

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
    json_bytes = sum(len(t.encode()) for _, texts in windows for t in texts)

    encoded = [codec.encode(s, t) for s, t in windows]
    for (s, t), data in zip(windows, encoded):  # the benchmark only counts exact round trips
        assert codec.decode(data, count=len(t), raw_len=raw_size(s, t)) == (s, t)
    lz = [lzma.compress("".join(t).encode(), preset=6) for _, t in windows]
    whole_lz = len(lzma.compress("".join(t for _, ts in windows for t in ts).encode(), preset=6))

    enc_s = median_time(lambda: [codec.encode(s, t) for s, t in windows], runs)
    lz_s = median_time(lambda: [lzma.compress("".join(t).encode(), preset=6) for _, t in windows], runs)
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


# A JSON string (kept whole, so digits inside it are not numbers) or a number token.
_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|-?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?')


def age_text(text: str, digits: int) -> str:
    """Every float token (one with '.' or an exponent) rounded to `digits` places, fixed-point."""
    quantum = decimal.Decimal(1).scaleb(-digits)

    def rounded(match: re.Match) -> str:
        token = match.group()
        if token[0] == '"' or not any(c in token for c in ".eE"):
            return token
        with decimal.localcontext(prec=1000):  # 1e300 to 3 places needs 304 digits
            value = decimal.Decimal(token).quantize(quantum)
        return format(value.copy_abs() if value.is_zero() else value, "f")  # never -0.000

    return _TOKEN.sub(rounded, text)


def _encoded_size(version: int, windows: list) -> int:
    codec = ColumnarCodec(version=version)
    total = 0
    for s, t in windows:
        data = codec.encode(s, t)
        assert codec.decode(data, count=len(t), raw_len=raw_size(s, t)) == (s, t)
        total += len(data)
    return total


def bench_aged(file: str, topic: str, window: int, digits: int) -> dict:
    """Bytes of one topic before and after rounding, in format versions 3 and 4 and LZMA-6."""
    messages = load_topic(file, topic)
    windows = [messages[i : i + window] for i in range(0, len(messages), window)]
    windows = [([s for s, _ in w], [t for _, t in w]) for w in windows]
    aged = [(s, [age_text(t, digits) for t in texts]) for s, texts in windows]
    return {
        "file": file,
        "topic": topic,
        "digits": digits,
        "original_v3": _encoded_size(3, windows),
        "original_v4": _encoded_size(4, windows),
        "aged_json": sum(len(t.encode()) for _, texts in aged for t in texts),
        "aged_v3": _encoded_size(3, aged),
        "aged_v4": _encoded_size(4, aged),
        "aged_lzma6_windows": sum(len(lzma.compress("".join(t).encode(), preset=6)) for _, t in aged),
    }


def print_aged(window: int, digits: list[int]) -> None:
    print(f"aged data: float tokens rounded to D places, {window}-message windows, bytes")
    print(
        f"{'file':20} {'topic':11} {'D':>2} {'orig v3':>8} {'orig v4':>8} {'aged json':>10} "
        f"{'aged v3':>8} {'aged v4':>8} {'v4/v3':>6} {'aged lzma6':>10}"
    )
    for file, topic in TOPICS:
        for d in digits:
            r = bench_aged(file, topic, window, d)
            print(
                f"{file:20} {topic:11} {d:2d} {r['original_v3']:8d} {r['original_v4']:8d} "
                f"{r['aged_json']:10d} {r['aged_v3']:8d} {r['aged_v4']:8d} "
                f"{r['aged_v4'] / r['aged_v3']:6.3f} {r['aged_lzma6_windows']:10d}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--window", type=int, default=200)
    parser.add_argument("--aged", type=int, nargs="+", metavar="D",
                        help="only compare sizes after rounding floats to D places (1..18)")
    args = parser.parse_args()
    if args.aged:
        print_aged(args.window, args.aged)
        return
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
