"""The paper's Table 2 on real data, extended: general compressors, MCAP and columnar.

Usage: python bench/compression.py [--file nav2_turtlebot.mcap] [--topic /odom ...]
                                   [--runs 3] [--out out/compression.json]
The JSON log is the JSONL form used across cclogfs, one line per message:
{"topic": ..., "stamp_ns": ..., "msg": <rosbridge JSON>}. Every scheme must give those
bytes back (MCAP gives back the CDR messages the JSON was made from). Speeds are MB of
JSON log per second (for MCAP too, so the columns compare), medians over --runs.
"""

from __future__ import annotations

import argparse
import gzip  # noqa: F401  (tarfile's w:gz needs it; imported to fail early when missing)
import io
import json
import lzma
import sys
import tarfile
import zipfile
from pathlib import Path

import lz4.frame
import zstandard

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench._util import DATA, median_time  # noqa: E402
from cclogfs.codecs import codec_from_config, raw_size  # noqa: E402
from cclogfs.jsontext.ros import message_to_json  # noqa: E402

try:
    import liblzfse  # pyliblzfse, the reference LZFSE implementation
except ImportError:  # pragma: no cover - optional
    liblzfse = None


def load(file: str, topics: list[str]):
    """JSONL lines per topic, and the raw CDR messages with their schemas, in log order."""
    from rosbags.highlevel import AnyReader

    lines: dict[str, list[tuple[int, bytes]]] = {t: [] for t in topics}
    cdr = []
    with AnyReader([DATA / file]) as reader:
        cons = [c for c in reader.connections if c.topic in topics]
        for con, stamp, raw in reader.messages(connections=cons):
            msg = reader.deserialize(raw, con.msgtype)
            line = '{"topic": %s, "stamp_ns": %d, "msg": %s}\n' % (
                json.dumps(con.topic), stamp, message_to_json(msg))
            lines[con.topic].append((stamp, line.encode()))
            cdr.append((con, stamp, bytes(raw) if reader.is2 else reader.ros1_to_cdr(raw, con.msgtype)))
    return lines, cdr


def mcap_bytes(cdr) -> bytes:
    """The messages as `ros2 bag record` writes them: MCAP, ros2msg schemas, zstd chunks."""
    from mcap.writer import CompressionType, Writer

    buf = io.BytesIO()
    writer = Writer(buf, compression=CompressionType.ZSTD)
    writer.start(profile="ros2", library="cclogfs-bench")
    channels: dict[int, int] = {}
    for con, stamp, data in cdr:
        if con.id not in channels:
            schema = writer.register_schema(
                name=con.msgtype, encoding="ros2msg", data=con.msgdef.data.encode()
            )
            channels[con.id] = writer.register_channel(con.topic, "cdr", schema)
        writer.add_message(channels[con.id], log_time=stamp, data=data, publish_time=stamp)
    writer.finish()
    return buf.getvalue()


def read_mcap(data: bytes) -> int:
    from mcap.reader import make_reader

    return sum(len(m.data) for _, _, m in make_reader(io.BytesIO(data)).iter_messages())


def zip_bytes(log: bytes) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("log.jsonl", log)
    return buf.getvalue()


def unzip(data: bytes) -> bytes:
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return z.read("log.jsonl")


def tgz_bytes(log: bytes) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        info = tarfile.TarInfo("log.jsonl")
        info.size = len(log)
        tar.addfile(info, io.BytesIO(log))
    return buf.getvalue()


def untgz(data: bytes) -> bytes:
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as tar:
        return tar.extractfile("log.jsonl").read()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--file", default="nav2_turtlebot.mcap")
    parser.add_argument("--topic", action="append", help="repeatable; default /odom")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--window", type=int, default=200)
    parser.add_argument("--out", default="out/compression.json")
    args = parser.parse_args()
    topics = args.topic or ["/odom"]
    lines, cdr = load(args.file, topics)
    ordered = sorted((s, t) for msgs in lines.values() for s, t in msgs)
    log = b"".join(t for _, t in ordered)
    count = len(ordered)
    zc, zd = {lvl: zstandard.ZstdCompressor(level=lvl) for lvl in (3, 19)}, zstandard.ZstdDecompressor()
    columnar = codec_from_config("columnar")
    windows = [
        ([s for s, _ in msgs[i : i + args.window]], [t for _, t in msgs[i : i + args.window]])
        for msgs in lines.values()
        for i in range(0, len(msgs), args.window)
    ]

    def col_encode():
        return [columnar.encode(s, t) for s, t in windows]

    def col_decode(payloads):
        return [columnar.decode(p, count=len(t), raw_len=raw_size(s, t)) for (s, t), p in zip(windows, payloads)]

    schemes = [
        ("None", lambda b: b, lambda d: d),
        ("LZ4", lz4.frame.compress, lz4.frame.decompress),
        ("LZFSE", liblzfse.compress, liblzfse.decompress) if liblzfse else ("LZFSE", None, None),
        ("ZIP (deflate)", zip_bytes, unzip),
        ("tar+gzip", tgz_bytes, untgz),
        ("LZMA-6", lambda b: lzma.compress(b, preset=6), lzma.decompress),
        ("zstd-3", zc[3].compress, zd.decompress),
        ("zstd-19", zc[19].compress, zd.decompress),
    ]
    rows = []
    for name, comp, decomp in schemes:
        if comp is None:
            rows.append({"scheme": name, "note": "unavailable: pyliblzfse is not installed"})
            continue
        data = comp(log)
        assert decomp(data) == log, name
        rows.append({"scheme": name, "bytes": len(data), "ct": median_time(lambda: comp(log), args.runs),
                     "dt": median_time(lambda: decomp(data), args.runs)})
    mcap = mcap_bytes(cdr)
    assert read_mcap(mcap) == sum(len(d) for _, _, d in cdr)
    rows.append({"scheme": "MCAP, zstd chunks (CDR)", "bytes": len(mcap),
                 "ct": median_time(lambda: mcap_bytes(cdr), args.runs),
                 "dt": median_time(lambda: read_mcap(mcap), args.runs)})
    payloads = col_encode()
    assert [x for x in col_decode(payloads)] == windows
    rows.append({"scheme": f"cclogfs columnar ({args.window}-msg windows)", "bytes": sum(map(len, payloads)),
                 "ct": median_time(col_encode, args.runs), "dt": median_time(lambda: col_decode(payloads), args.runs)})

    mb = len(log) / 1e6
    print(f"{args.file} {', '.join(topics)}: {count} messages, {len(log)} bytes of JSON log "
          f"(medians of {args.runs} runs)")
    print(f"{'scheme':36} {'size':>10} {'% JSON':>7} {'B/msg':>7} {'comp MB/s':>9} {'dec MB/s':>9}")
    for r in rows:
        if "bytes" not in r:
            print(f"{r['scheme']:36} {r['note']}")
            continue
        r["pct_of_json"] = 100 * r["bytes"] / len(log)
        r["bytes_per_msg"] = r["bytes"] / count
        stored = r["scheme"] == "None"  # nothing to time: a copy
        ct, dt = r.pop("ct"), r.pop("dt")
        r["compress_mb_s"] = None if stored else mb / ct
        r["decompress_mb_s"] = None if stored else mb / dt
        speeds = "        -         -" if stored else f"{r['compress_mb_s']:9.1f} {r['decompress_mb_s']:9.1f}"
        print(f"{r['scheme']:36} {r['bytes']:10d} {r['pct_of_json']:7.2f} {r['bytes_per_msg']:7.1f} {speeds}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"file": args.file, "topics": topics, "messages": count,
                               "json_bytes": len(log), "runs": args.runs, "rows": rows}, indent=1) + "\n")
    print(f"saved {out}")


if __name__ == "__main__":
    main()
