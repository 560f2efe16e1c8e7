"""Issue 14, "Speed on a robot's CPU": every row of its table beside its anchors, one run.

    python3 dev.py bench speed [--messages 300000] [--rounds 3] [--big 1000000]

Input: real wheel odometry (/odom of every MCAP file in ../shared/data, converted the way
cclogfs converts it), repeated with later stamps up to --messages, as JSONL; a ROS 1 bag of a
simulated run (/odom + /imu); a store of --big messages of the same odometry, and the same
messages in an indexed MCAP file (JSON channels) for the MCAP reader.

Rounds are interleaved (every case once per round) and each figure is the median over
the rounds; ratios are against anchors measured in the same rounds, so they hold on a busy
machine. `record` runs the real CLI in a child process whose timer starts after imports;
`cat` and `--help` are timed as whole processes (what a user waits for).
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import lzma
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ._util import OUT, SHARED, machine, save_json, topic_messages

ROOT = Path(__file__).resolve().parent.parent
CCLOG = Path(sys.executable).parent / "cclog"
SECOND = 1_000_000_000
OPEN_SIZES = (10_000, 100_000)  # stores opened beside the --big one

# A child running one `cclog` command; every module the command needs is imported before
# the timer starts (the issue's figures are CPU time after imports).
CHILD = """
import sys, time
from bench._util import peak_rss_mib
import cclogfs.cli.record, cclogfs.cli.cat, cclogfs.pipeline, cclogfs.ingest.jsonl, cclogfs.ingest.rosbag
import cclogfs.codecs.columnar, cclogfs.classifier, cclogfs.export, rosbags.highlevel
from cclogfs.cli import main
t = time.perf_counter()
code = main(sys.argv[1:])
print(time.perf_counter() - t, peak_rss_mib(), code, file=sys.stderr)
"""

# The MCAP anchor for `cat`: its indexed reader printing one second of messages as JSONL.
MCAP_CAT = """
import sys
from mcap.reader import make_reader
start, end = int(sys.argv[2]), int(sys.argv[3])
out = sys.stdout.buffer
with open(sys.argv[1], "rb") as f:
    for _, channel, m in make_reader(f).iter_messages(start_time=start, end_time=end + 1):
        out.write(b'{"topic": "%s", "stamp_ns": %d, "msg": %s}\\n' % (channel.topic.encode(), m.log_time, m.data))
"""


def odometry(n: int) -> list[tuple[int, str]]:
    """n real /odom messages: every shared MCAP file's /odom, repeated with later stamps."""
    base: list[tuple[int, str]] = []
    for path in sorted(SHARED.rglob("*.mcap")):
        msgs = topic_messages(path, "/odom")
        if not msgs:
            continue
        t0 = msgs[0][0]
        offset = base[-1][0] + 40_000_000 if base else 0
        base += [(s - t0 + offset, text) for s, text in msgs]
    if not base:
        raise SystemExit(f"no /odom in {SHARED}")
    out, span = [], base[-1][0] + 40_000_000
    for k in range(n // len(base) + 1):
        out += [(s + k * span + 1_600_000_000 * SECOND, t) for s, t in base]
    return out[:n]


def write_jsonl(path: Path, msgs: list[tuple[int, str]]) -> None:
    with open(path, "w", encoding="utf-8") as f:
        for s, t in msgs:
            f.write(f'{{"topic": "/odom", "stamp_ns": {s}, "msg": {t}}}\n')


def write_mcap(path: Path, msgs: list[tuple[int, str]]) -> None:
    from mcap.writer import Writer

    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("nav_msgs/msg/Odometry", "jsonschema", b"{}")
        channel = w.register_channel("/odom", "json", schema)
        for s, t in msgs:
            w.add_message(channel, log_time=s, data=t.encode(), publish_time=s)
        w.finish()


def write_ros1_bag(path: Path, minutes: float) -> int:
    """A ROS 1 bag of a simulated run (/odom, /imu); returns its message count."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    from cclogfs.sim import simulate

    run = simulate(seed=7, duration_s=minutes * 60, rate_hz=100, anomalies=int(minutes))
    tmp = path.with_suffix(".ros2")
    run.write_bag(tmp, topics=("/odom", "/imu"))
    ros1 = get_typestore(Stores.ROS1_NOETIC)

    def to_ros1(obj):  # the same message as ROS 1 types (a Header gains its seq)
        if not dataclasses.is_dataclass(obj):
            return obj
        cls = ros1.types[obj.__msgtype__]
        names = [f.name for f in dataclasses.fields(cls) if f.default is dataclasses.MISSING]
        return cls(**{k: to_ros1(getattr(obj, k)) if hasattr(obj, k) else 0 for k in names})

    n = 0
    with AnyReader([tmp]) as reader, Writer(path) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=ros1) for c in reader.connections}
        for con, t, raw in reader.messages():
            msg = to_ros1(reader.deserialize(raw, con.msgtype))
            writer.write(conns[con.id], t, ros1.serialize_ros1(msg, con.msgtype))
            n += 1
    shutil.rmtree(tmp)
    return n


def run_cli(args: list[str], stdin: Path | None = None) -> tuple[float, float]:
    """(seconds after imports, peak RSS MiB) of `cclog ARGS` in a child process."""
    with open(stdin or os.devnull, "rb") as f:
        out = subprocess.run([sys.executable, "-c", CHILD, *args], stdin=f, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True, cwd=ROOT)  # fmt: skip
    *_, last = out.stderr.strip().splitlines() or ["?"]
    secs, rss, code = last.split()
    if code != "0":
        raise RuntimeError(f"cclog {' '.join(args)} exited {code}: {out.stderr}")
    return float(secs), float(rss)


def whole_process(cmd: list[str]) -> float:
    """Wall seconds of a command from exec to exit, output to /dev/null."""
    t = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, check=True, cwd=ROOT)
    return time.perf_counter() - t


def timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def lines_of(path: Path) -> list[bytes]:
    return path.read_bytes().splitlines(keepends=True)


def orjson_loads(lines: list[bytes]) -> None:
    import orjson

    for line in lines:
        orjson.loads(line)


def lzma6(data: bytes) -> None:
    lzma.compress(data, preset=6)


def zstd3(data: bytes) -> None:
    import zstandard

    zstandard.ZstdCompressor(level=3).compress(data)


def rosbags_read(bag: Path) -> None:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        for con, _, raw in reader.messages():
            reader.deserialize(raw, con.msgtype)


def mcap_scan(path: Path) -> None:
    """The MCAP reader over every message, written as JSONL to a sink (what `cat` does)."""
    from mcap.reader import make_reader

    out = io.BytesIO()
    with open(path, "rb") as f:
        for _, channel, m in make_reader(f).iter_messages():
            out.write(b'{"topic": "%s", "stamp_ns": %d, "msg": %s}\n' % (channel.topic.encode(), m.log_time, m.data))
            if out.tell() > 1 << 24:
                out.seek(0)


def open_time(store: Path) -> float:
    from cclogfs.store import open_store

    t = time.perf_counter()
    s = open_store(store, readonly=True)
    elapsed = time.perf_counter() - t
    s.close()
    return elapsed


def append_open_time(store: Path, work: Path) -> float:
    """Opening a copy of `store` for append: the writer checks its active segment whole, so
    that damage below the synced point is named before it appends (FORMAT.md): by one hash
    of the bytes below a clean close's checkpoint (`checkpoint.xxh3`), else by a scan."""
    from cclogfs.store import open_store

    copy = work / "append.store"
    shutil.copytree(store, copy)
    t = time.perf_counter()
    s = open_store(copy)
    elapsed = time.perf_counter() - t
    s.close()
    shutil.rmtree(copy)
    return elapsed


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--messages", type=int, default=300_000, help="odometry messages to record")
    ap.add_argument("--big", type=int, default=1_000_000, help="messages in the store `cat` reads")
    ap.add_argument("--bag-minutes", type=float, default=5.0, help="simulated minutes in the ROS 1 bag")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--only", nargs="*", help="run only the cases whose name holds one of these words")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    # The inputs take minutes to make (a 1M-message store): kept in out/ between runs.
    # Everything timed writes into a fresh temporary directory.
    # v2: the stores are closed by a version that writes the checkpoint index (issue 14);
    # v3: and its digest (checkpoint.xxh3), which the writer's open checks instead of a scan.
    data = OUT / f"speed-data-{args.messages}-{args.big}-{args.bag_minutes:g}-v3"
    if not (data / "done").exists():
        shutil.rmtree(data, ignore_errors=True)
        data.mkdir(parents=True)
        make_inputs(args, data)
        (data / "done").write_text("")
    work = Path(tempfile.mkdtemp(prefix="speed-", dir=OUT))
    try:
        return measure(args, data, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def make_inputs(args, data: Path) -> None:
    from cclogfs.classifier import train
    from cclogfs.sim import simulate

    write_jsonl(data / "odom.jsonl", odometry(args.messages))
    (data / "bag_count").write_text(str(write_ros1_bag(data / "sim.bag", args.bag_minutes)))
    train([[t for _, t in simulate(seed=s, duration_s=90, rate_hz=100).messages] for s in (1, 2)]).save(data / "model")
    big = odometry(args.big)
    write_jsonl(data / "big.jsonl", big)
    write_mcap(data / "big.mcap", big)
    mid = big[len(big) // 2][0]
    (data / "one_s").write_text(f"{mid} {mid + SECOND} {sum(1 for s, _ in big if mid <= s <= mid + SECOND)}")
    # Made with the code of the day, but the format does not change: before and after read the same.
    run_cli(["record", str(data / "big.jsonl"), "--store", str(data / "big.store")])
    for n in OPEN_SIZES:  # the first n of the same messages, for open time against store size
        with open(data / "big.jsonl", "rb") as src, open(data / "part.jsonl", "wb") as dst:
            dst.writelines(line for _, line in zip(range(n), src))
        run_cli(["record", str(data / "part.jsonl"), "--store", str(data / f"open-{n}.store")])
    (data / "part.jsonl").unlink()
    (data / "big.jsonl").unlink()
    run_cli(["record", str(data / "odom.jsonl"), "--store", str(data / "small.store")])


def measure(args, data: Path, work: Path) -> int:
    print(f"machine: {machine()}", flush=True)
    # An installed package has its bytecode compiled (pip does it at install); a checkout
    # run with PYTHONDONTWRITEBYTECODE=1 would compile every cclogfs module in every child
    # (on this machine, most of `cclog cat`'s start-up), while the anchors' packages are
    # compiled: compile ours once, as an install would.
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "cclogfs")], check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    jsonl, bag, model = data / "odom.jsonl", data / "sim.bag", data / "model"
    big_store, big_mcap, small_store = data / "big.store", data / "big.mcap", data / "small.store"
    lines = lines_of(jsonl)
    msgs = [(int(s), t) for s, t in (line_parts(x) for x in lines)]
    n = len(lines)
    # LZMA-6 runs at a few MB/s: a tenth of the file gives its rate as well as the whole.
    sample = b"".join(lines[: n // 10])
    n_bag = int((data / "bag_count").read_text())
    start, end, n_one_s = (data / "one_s").read_text().split()
    one_s, n_one_s = [start, end], int(n_one_s)
    print(f"input: {n:,} odometry lines ({jsonl.stat().st_size / 1e6:.1f} MB); ROS 1 bag {n_bag:,} messages; "
          f"store of {args.big:,} messages; 1 s = {n_one_s} messages; {args.rounds} interleaved rounds",
          flush=True)  # fmt: skip
    fresh = iter(range(10**9))

    def store() -> str:
        return str(work / f"s{next(fresh)}")

    # name: (messages, fn -> seconds, or (seconds, peak RSS MiB) for a child `cclog`)
    cases = {
        "orjson.loads per line": (n, lambda: timed(lambda: orjson_loads(lines))),
        "LZMA-6 of the JSONL": (n // 10, lambda: timed(lambda: lzma6(sample))),
        "zstd-3 of the JSONL": (n // 10, lambda: timed(lambda: zstd3(sample))),
        "MCAP writer (JSON)": (n, lambda: timed(lambda: write_mcap(work / "w.mcap", msgs))),
        "record JSONL, columnar": (n, lambda: run_cli(["record", str(jsonl), "--store", store()])),
        "record JSONL, zstd": (n, lambda: run_cli(["record", str(jsonl), "--store", store(), "--codec", "zstd"])),
        "record JSONL, smart": (n, lambda: run_cli(["record", str(jsonl), "--store", store(), "--model", str(model),
                                                     "--force-model"])),  # a simulated robot's model on real /odom
        "rosbags read+deserialise": (n_bag, lambda: timed(lambda: rosbags_read(bag))),
        "record ROS 1 bag, columnar": (n_bag, lambda: run_cli(["record", str(bag), "--store", store()])),
        "cat 1 s, whole process": (n_one_s, lambda: whole_process(
            [str(CCLOG), "cat", str(big_store), "--start", one_s[0], "--end", one_s[1]])),
        "MCAP reader 1 s, whole process": (n_one_s, lambda: whole_process(
            [sys.executable, "-W", "ignore::DeprecationWarning", "-c", MCAP_CAT, str(big_mcap), *one_s])),
        "cclog --help, whole process": (1, lambda: whole_process([str(CCLOG), "--help"])),
        "python -c pass, whole process": (1, lambda: whole_process([sys.executable, "-c", "pass"])),
        "full scan, cat to JSONL": (n, lambda: run_cli(["cat", str(small_store)])),
        "MCAP reader full scan": (n, lambda: timed(lambda: mcap_scan(work / "w.mcap"))),
        **{f"open after clean close, {k:,} msgs": (1, lambda k=k: open_time(data / f"open-{k}.store"))
           for k in OPEN_SIZES},
        f"open after clean close, {args.big:,} msgs": (1, lambda: open_time(big_store)),
        **{f"open for append, {k:,} msgs": (1, lambda k=k: append_open_time(data / f"open-{k}.store", work))
           for k in OPEN_SIZES},
        f"open for append, {args.big:,} msgs": (1, lambda: append_open_time(big_store, work)),
    }  # fmt: skip
    if args.only:
        cases = {k: v for k, v in cases.items() if any(o in k for o in args.only)}
    write_mcap(work / "w.mcap", msgs)  # for the full scan, whether or not the writer is timed
    secs: dict[str, list[float]] = {k: [] for k in cases}
    rss: dict[str, float] = {}
    for r in range(args.rounds):
        for name, (_, fn) in cases.items():
            got = fn()
            if isinstance(got, tuple):
                got, rss[name] = got[0], max(rss.get(name, 0.0), got[1])
            secs[name].append(got)
            for p in work.glob("s[0-9]*"):
                shutil.rmtree(p)
        print(f"round {r + 1} done", flush=True)
    med = {k: statistics.median(v) for k, v in secs.items()}
    rate = {k: cases[k][0] / med[k] for k in med}
    rows = []
    print(f"\n{'case':<44} {'median':>10} {'msg/s':>10} {'peak RSS':>9}")
    for k in cases:
        extra = f"{rss[k]:7.0f} MiB" if k in rss else ""
        print(f"{k:<44} {med[k] * 1e3:8.1f}ms {rate[k]:>10,.0f} {extra}")
        rows.append({"case": k, "median_s": med[k], "all_s": secs[k], "msg_per_s": rate[k], "peak_rss_mib": rss.get(k)})
    ratios = report_ratios(rate, med)
    path = save_json("bench-speed.json", {"machine": machine(), "rows": rows, "ratios": ratios})
    print(f"saved {path}")
    return 0


def line_parts(line: bytes) -> tuple[str, str]:
    """(stamp, msg text) of a line write_jsonl wrote."""
    head, _, rest = line.partition(b', "msg": ')
    return head.rsplit(b" ", 1)[1].decode(), rest[:-2].decode()


def report_ratios(rate: dict[str, float], med: dict[str, float]) -> list[dict]:
    """The issue's targets: ratios against anchors of the same rounds, and absolute figures."""
    relative = [
        ("record JSONL, columnar", "orjson.loads per line", 0.4),
        ("record JSONL, columnar", "LZMA-6 of the JSONL", 20.0),
        ("record ROS 1 bag, columnar", "rosbags read+deserialise", 0.6),
        ("full scan, cat to JSONL", "MCAP reader full scan", 1.5),
    ]
    absolute = [("record JSONL, columnar", 100_000), ("record ROS 1 bag, columnar", 50_000),
                ("record JSONL, smart", 100_000)]  # fmt: skip
    out = []
    print(f"\n{'target':<66} {'figure':>10} {'needed':>9} {'met':>4}")

    def row(label: str, figure: float, needed: float, met: bool, fmt: str) -> None:
        print(f"{label:<66} {figure:>10{fmt}} {needed:>9{fmt}} {'yes' if met else 'NO':>4}")
        out.append({"target": label, "figure": figure, "needed": needed, "met": met})

    for case, anchor, need in relative:
        if case in rate and anchor in rate:
            ratio = rate[case] / rate[anchor]
            row(f"{case} / {anchor} (msg/s ratio)", ratio, need, ratio >= need, ".2f")
    smallest = f"open after clean close, {OPEN_SIZES[0]:,} msgs"
    for case in [k for k in med if k.startswith("open after clean close") and k != smallest]:
        if smallest in med:  # independent of store size: at most noise apart
            ratio = med[case] / med[smallest]
            row(f"{case} / {OPEN_SIZES[0]:,} msgs (time ratio)", ratio, 2.0, ratio <= 2.0, ".2f")
    case, anchor = "cat 1 s, whole process", "MCAP reader 1 s, whole process"
    if case in med and anchor in med:
        ratio = med[case] / med[anchor]
        row(f"{case} / {anchor} (time ratio)", ratio, 2.5, ratio <= 2.5, ".2f")
    for case, need in absolute:
        if case in rate:
            row(f"{case} (msg/s)", rate[case], need, rate[case] >= need, ",.0f")
    for case, limit in [("cat 1 s, whole process", 150.0), ("cclog --help, whole process", 100.0)]:
        if case in med:
            row(f"{case} (ms)", med[case] * 1e3, limit, med[case] * 1e3 <= limit, ".1f")
    # The absolute targets were set on a host where the anchors ran at ISSUE_ANCHORS. On a
    # slower or busier one, the same target is the figure that bears the same ratio to the
    # anchor of this run: reported beside the absolute rows, not instead of them.
    print("absolute targets at the issue's anchor speeds (figure x issue anchor / this run's anchor):")
    for case, anchor, need in AT_ISSUE_SPEED:
        if case in rate and anchor in rate:
            scaled = rate[case] * ISSUE_ANCHORS[anchor] / rate[anchor]
            row(f"{case}, at {anchor} {ISSUE_ANCHORS[anchor]:,.0f}/s", scaled, need, scaled >= need, ",.0f")
    case, anchor = "cat 1 s, whole process", "MCAP reader 1 s, whole process"
    if case in med and anchor in med:
        scaled = med[case] / med[anchor] * ISSUE_ANCHORS[anchor] * 1e3
        row(f"{case}, at MCAP 1 s in {ISSUE_ANCHORS[anchor] * 1e3:.0f} ms (ms)", scaled, 150.0, scaled <= 150.0, ".1f")
    return out


# The anchors as issue 14 measured them on its host (msg/s; the MCAP whole process in s).
ISSUE_ANCHORS = {"orjson.loads per line": 342_000, "rosbags read+deserialise": 74_000,
                 "MCAP reader 1 s, whole process": 0.070}  # fmt: skip

# Each absolute msg/s target of issue 14: (case, its anchor, msg/s needed).
AT_ISSUE_SPEED = [("record JSONL, columnar", "orjson.loads per line", 100_000),
                  ("record JSONL, smart", "orjson.loads per line", 100_000),
                  ("record ROS 1 bag, columnar", "rosbags read+deserialise", 50_000)]  # fmt: skip
