"""Live ROS 1 smart logging against `rosbag record`, on the same playback, in the same run.

    python3 dev.py bench live_ros1 [--rates 1,10] [--bag PATH]

A private roscore; the real Nav2 TurtleBot run (../shared/data/nav2_turtlebot.mcap: /odom,
/tf, /tf_static, /amcl_pose, 97 s) as a ROS 1 bag; at each rate, `cclog record ros1://
--model M` (smart logging, model trained on the run's own /odom) and `rosbag record` of
the same topics both subscribe, then `rosbag play --rate R` plays the bag once. Reported:
each recorder's CPU time (user + system, from wait4, children included: `rosbag record`
runs its C++ recorder as a child), in all and per message net of start-up (the CPU of a
run that starts, subscribes, idles 3 s and stops); and the messages each one received
against the bag's, per topic. (Idle CPU per second was also tried as a correction: on this
shared machine it varied 2x between runs, more than the figure it would correct.) `rosbag play --delay 2` gives both time to
connect before the first message. Loss is reported as measured, never hidden, next to
what cclog itself reported lost from header.seq (and its exit status: 4 when it knew).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench._util import OUT, SHARED, machine
from cclogfs.ingest import open_source
from cclogfs.ingest.ros1testing import play, roscore, ros1_missing, start, subscribers, wait_for, write_ros1_bag

CCLOG = [sys.executable, "-m", "cclogfs"]


def stop_cpu(proc: subprocess.Popen, *, child: bool = False, timeout: float = 60.0) -> float:
    """SIGINT the process (with `child`: its children instead), reap it with wait4; its CPU
    seconds (user + system, including the children it waited for).

    `rosbag record` is a Python wrapper that runs the C++ recorder as a child; SIGINT to
    the wrapper makes it exit without waiting for the child (which then closes the bag as
    an orphan, its CPU time lost). SIGINT to the child ends it, and the wrapper's wait
    returns: the wrapper's rusage then holds both."""
    children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split() if child else []
    for pid in children or [proc.pid]:
        os.kill(int(pid), signal.SIGINT)
    deadline = time.monotonic() + timeout
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return usage.ru_utime + usage.ru_stime
        if time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            deadline = float("inf")
        time.sleep(0.05)


def recorders(env, tmp: Path, tag: str, topics: list[str], model: Path):
    cclog = start([*CCLOG, "record", "ros1://", "--store", str(tmp / f"{tag}.store"), "--model", str(model),
                   *[a for t in topics for a in ("--topic", t)]], env, stdout=subprocess.DEVNULL,
                  stderr=open(tmp / f"{tag}.cclog.err", "w"))  # fmt: skip
    rosbag = start(["rosbag", "record", "-q", "-O", str(tmp / f"{tag}.bag"), *topics], env,
                   stdout=subprocess.DEVNULL, stderr=open(tmp / f"{tag}.rosbag.err", "w"))  # fmt: skip
    for t in topics:  # both subscribed to every topic before anything is played
        wait_for(lambda t=t: sum(n.startswith(("/cclog_record", "/record")) for n in subscribers(env, t)) >= 2,
                 60, f"both recorders on {t}")  # fmt: skip
    time.sleep(1.0)
    return cclog, rosbag


def received_cclog(err_path: Path) -> dict[str, int]:
    line = next((x for x in err_path.read_text().splitlines() if "stopped by SIGINT; received" in x), "")
    return {t: int(n.replace(",", "")) for t, n in re.findall(r"(/\S+) ([\d,]+)", line.split("received", 1)[-1])}


def reported_lost(err_path: Path) -> dict[str, int | str]:
    """What cclog itself reported lost per topic (from header.seq), or why it could not tell."""
    out: dict[str, int | str] = {}
    for topic, rest in re.findall(r"^  (/\S+): [\d,]+ received, (.*)$", err_path.read_text(), re.MULTILINE):
        m = re.fullmatch(r"([\d,]+) lost", rest)
        out[topic] = int(m.group(1).replace(",", "")) if m else "not checked"
    return out


def received_bag(path: Path) -> dict[str, int]:
    out: dict[str, int] = {}
    with open_source(path) as src:
        for m in src:
            out[m.topic] = out.get(m.topic, 0) + 1
    return out


def one_rate(env, tmp: Path, bag: Path, model: Path, topics: list[str], want: dict[str, int], rate: float) -> dict:
    tag = f"r{rate:g}"
    cclog, rosbag = recorders(env, tmp, tag, topics, model)
    t0 = time.monotonic()
    player = play(env, bag, "--rate", str(rate), "--delay", "2")  # both connect before the first message
    player.communicate()
    wall = time.monotonic() - t0
    time.sleep(1.0)
    cpu = {"cclog": stop_cpu(cclog), "rosbag": stop_cpu(rosbag, child=True)}
    got = {"cclog": received_cclog(tmp / f"{tag}.cclog.err"), "rosbag": received_bag(tmp / f"{tag}.bag")}
    n = sum(want.values())
    return {
        "rate": rate, "play_wall_s": round(wall, 2), "messages": n, "cpu_s": cpu,
        "lost": {k: {t: want[t] - v.get(t, 0) for t in topics} for k, v in got.items()},
        "cclog_reported_lost": reported_lost(tmp / f"{tag}.cclog.err"), "cclog_exit": cclog.returncode,
    }  # fmt: skip


def idle_cpu(env, tmp: Path, model: Path, topics: list[str], seconds: float) -> dict[str, float]:
    """CPU of each recorder over a run that receives nothing (start-up, subscribing, idle)."""
    cclog, rosbag = recorders(env, tmp, f"idle{seconds:g}", topics, model)
    time.sleep(seconds)
    return {"cclog": stop_cpu(cclog), "rosbag": stop_cpu(rosbag, child=True)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", default="1,10")
    ap.add_argument("--bag", type=Path, default=SHARED / "nav2_turtlebot.mcap")
    args = ap.parse_args()
    if (why := ros1_missing()) is not None:
        print(f"live_ros1: {why}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory(prefix="cclog-live-") as d:
        tmp = Path(d)
        bag = write_ros1_bag(args.bag, tmp / "play.bag")
        with open_source(bag) as src:
            want: dict[str, int] = {}
            for m in src:
                want[m.topic] = want.get(m.topic, 0) + 1
        topics = sorted(want)
        subprocess.run([*CCLOG, "train", str(args.bag), "--out", str(tmp / "model")], check=True, capture_output=True)
        with roscore(tmp) as env:
            startup = idle_cpu(env, tmp, tmp / "model", topics, 3.0)
            runs = [one_rate(env, tmp, bag, tmp / "model", topics, want, float(r)) for r in args.rates.split(",")]
    for r in runs:
        r["cpu_us_per_msg_net"] = {k: round(1e6 * (r["cpu_s"][k] - startup[k]) / r["messages"], 1) for k in startup}
    result = {"machine": machine(), "bag": str(args.bag), "messages": want, "startup_cpu_s": startup, "runs": runs}
    OUT.mkdir(exist_ok=True)
    (OUT / "live_ros1.json").write_text(json.dumps(result, indent=1))
    print(f"{args.bag.name} as a ROS 1 bag: {sum(want.values()):,} messages {want}")
    print(f"start-up (start, subscribe, 3 s idle, stop): cclog {startup['cclog']:.2f} s CPU, "
          f"rosbag record {startup['rosbag']:.2f} s")
    for r in runs:
        c, b = r["cpu_s"], r["cpu_us_per_msg_net"]
        print(f"rate {r['rate']:g}x ({r['play_wall_s']} s): CPU cclog smart {c['cclog']:.2f} s, rosbag record "
              f"{c['rosbag']:.2f} s; per message net of start-up {b['cclog']} us vs {b['rosbag']} us "
              f"({b['cclog'] / max(b['rosbag'], 1e-9):.1f}x)")  # fmt: skip
        print(f"  lost: cclog {r['lost']['cclog']}, rosbag record {r['lost']['rosbag']}")
        print(f"  cclog's own report (header.seq): {r['cclog_reported_lost']}, exit {r['cclog_exit']}")
    return 0
