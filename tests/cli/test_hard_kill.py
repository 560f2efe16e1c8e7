"""Issue 12 item 8: windows close after a bounded wall time as well as a bounded count, so
`kill -9` of a recording fed slowly through a pipe loses at most that plus the sync interval."""

import json
import subprocess
import sys
import time

import pytest

import cclogfs
from cclogfs.jsontext.lines import format_line

CCLOG = [sys.executable, "-m", "cclogfs"]


@pytest.mark.parametrize("smart", [False, True])
def test_kill_9_loses_at_most_the_window_bound(tmp_path, smart):
    extra = []
    if smart:  # a model that finds everything anomalous: one window that stays open
        extra = ["--model", str(anomalous_model(tmp_path)), "--force-model", "--no-summary", "--after", "1000"]
    proc = subprocess.Popen([*CCLOG, "record", "-", "--store", str(tmp_path / "s"), "--sync-ms", "100",
                             "--window-max-s", "1", *extra], stdin=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            text=True)  # fmt: skip
    sent = []
    try:
        t0 = time.monotonic()
        i = 0
        while time.monotonic() - t0 < 7:
            proc.stdin.write(odom_line(i))
            proc.stdin.flush()
            sent.append(time.monotonic())
            i += 1
            time.sleep(0.05)
        killed_at = time.monotonic()
        proc.kill()  # SIGKILL: no flush, no close
    finally:
        proc.wait()
    assert proc.returncode == -9
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        stored = sum(len(list(w.messages())) for w in store.query("/odom"))
    # 1 s window bound + 0.1 s sync, and 1.4 s of slack for a loaded machine.
    must = sum(1 for t in sent if t < killed_at - 2.5)
    assert stored >= must > 40, (stored, must, len(sent))


def odom_line(i: int, still: bool = False) -> str:
    x = 0.0 if still else 0.01 * i * (1 + i % 7)  # jerky motion
    msg = {"header": {"stamp": {"sec": 1000 + i // 20, "nanosec": (i % 20) * 50_000_000}, "frame_id": "odom"},
           "child_frame_id": "base", "pose": {"pose": {"position": {"x": x, "y": 0.0, "z": 0.0},
           "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}, "covariance": [0.0] * 36},
           "twist": {"twist": {"linear": {"x": 0.0 if still else 5.0 * (i % 3), "y": 0.0, "z": 0.0},
           "angular": {"x": 0.0, "y": 0.0, "z": 0.0 if still else 3.0 * (i % 2)}}, "covariance": [0.0] * 36}}  # fmt: skip
    return format_line("/odom", (1000 + i // 20) * 10**9 + (i % 20) * 50_000_000, json.dumps(msg))


def anomalous_model(tmp_path):
    """A model of a robot standing still: every moving message is anomalous."""
    from cclogfs.classifier import parse_odometry, train

    odom = parse_odometry(json.dumps(json.loads(odom_line(i, still=True))["msg"]) for i in range(600))
    model = train([odom])
    model.save(tmp_path / "m")
    return tmp_path / "m"
