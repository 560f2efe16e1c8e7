"""`cclog play` to JSONL: the pace, gaps, and the messages (no ROS needed)."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from cclogfs.play.pace import paced

CCLOG = [sys.executable, "-m", "cclogfs"]


class FakeClock:
    def __init__(self):
        self.now = 100.0
        self.sleeps = []

    def __call__(self):
        return self.now

    def sleep(self, s):
        self.sleeps.append(round(s, 6))
        self.now += s


def times(msgs, **kw):
    clock = FakeClock()
    out = []
    for m in paced(msgs, clock=clock, sleep=clock.sleep, **kw):
        out.append(round(clock.now - 100.0, 6))
    return out


S = 1_000_000_000


def test_paced_follows_stamps_scaled_by_rate():
    msgs = [("/a", 5 * S, "{}"), ("/b", 6 * S, "{}"), ("/a", 9 * S, "{}"), ("/a", 9 * S, "{}")]
    assert times(msgs) == [0.0, 1.0, 4.0, 4.0]
    assert times(msgs, rate=2.0) == [0.0, 0.5, 2.0, 2.0]


def test_paced_cuts_long_gaps_and_plays_backward_stamps_at_once():
    msgs = [("/a", 0, "{}"), ("/a", 1 * S, "{}"), ("/a", 100 * S, "{}"), ("/a", 101 * S, "{}"), ("/a", 50 * S, "{}")]
    assert times(msgs, skip_gaps_s=2.0) == [0.0, 1.0, 3.0, 4.0, 4.0]
    with pytest.raises(ValueError):
        list(paced(msgs, rate=0))


def test_play_jsonl_is_cat_with_types_at_the_recorded_pace(shared_data, tmp_path):
    bag = shared_data("tf_example.bag")  # 51.7 s of /tf and /tf_static
    subprocess.run([*CCLOG, "record", str(bag), "--store", str(tmp_path / "s")], check=True, capture_output=True)
    t0 = time.monotonic()
    r = subprocess.run([*CCLOG, "play", str(tmp_path / "s"), "--rate", "25"], capture_output=True, text=True, check=True)
    elapsed = time.monotonic() - t0
    cat = subprocess.run([*CCLOG, "cat", str(tmp_path / "s")], capture_output=True, text=True, check=True).stdout
    lines = [json.loads(x) for x in r.stdout.splitlines()]
    assert {x.pop("msgtype") for x in lines} == {"tf2_msgs/msg/TFMessage"}
    assert lines == [json.loads(x) for x in cat.splitlines()] and len(lines) == 518
    span = (lines[-1]["stamp_ns"] - lines[0]["stamp_ns"]) / 1e9
    assert span / 25 <= elapsed < span / 25 + 10  # paced, not dumped (the upper bound: start-up)
    assert "played 518 messages of 2 streams" in r.stderr


def test_play_refuses_what_it_cannot_do(shared_data, tmp_path):
    subprocess.run([*CCLOG, "record", str(shared_data("tf_example.bag")), "--store", str(tmp_path / "s")],
                   check=True, capture_output=True)  # fmt: skip
    for args, said in [(["--rate", "0"], "--rate must be positive"), (["--topic", "/nope"], "no message of /nope"),
                       (["--to", "udp://x"], "--to 'udp://x'"), (["--start", "1", "--end", "2"], "no message")]:  # fmt: skip
        r = subprocess.run([*CCLOG, "play", str(tmp_path / "s"), *args], capture_output=True, text=True)
        assert r.returncode == 1 and said in r.stderr and r.stderr.count("\n") == 1, (args, r.stderr)


def test_play_of_mixed_clocks_says_so_and_skip_gaps_plays_it(shared_data, tmp_path):
    # With --clock header /amcl_pose is in simulation time (924 s after 1970), /tf_static in wall time (2026)
    subprocess.run([*CCLOG, "record", str(shared_data("nav2_turtlebot.mcap")), "--store", str(tmp_path / "s"),
                    "--topic", "/amcl_pose", "--topic", "/tf_static", "--clock", "header"], check=True,
                   capture_output=True)  # fmt: skip
    proc = subprocess.Popen([*CCLOG, "play", str(tmp_path / "s"), "--rate", "100"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert "(streams on different clocks?); --skip-gaps S" in proc.stderr.readline()
    finally:
        proc.kill()
        proc.wait()
    r = subprocess.run([*CCLOG, "play", str(tmp_path / "s"), "--rate", "100", "--skip-gaps", "0.5"],
                       capture_output=True, text=True, timeout=120, check=True)  # fmt: skip
    assert len(r.stdout.splitlines()) == 136 and "note" not in r.stderr
