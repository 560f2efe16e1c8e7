"""Issue 16, kill -9 of live recording: `cclog record ros1://` (budget, aging) killed with
SIGKILL at a random instant while `rosbag play --loop` publishes a real bag and a reader
reads the store; after each kill the checks of tests/_kill9.py (fsck, repair, every window
the reader saw still there). Skips without ROS 1, fails without it under CI=true."""

from __future__ import annotations

import random
import subprocess
import sys
import time

from _kill9 import Reader, check_after_kill
from cclogfs.ingest.ros1testing import play, start, stop, wait_for
from test_ros1live import master, ros1  # noqa: F401 - the fixtures

LIVE_KILLS = 8


def test_kill_9_of_live_record_with_budget_and_aging(master, shared_data, tmp_path):  # noqa: F811
    player = play(master, shared_data("tf_example.bag"), "--loop", "--rate", "5")
    rng, reads = random.Random(4), 0
    try:
        for i in range(LIVE_KILLS):
            store = tmp_path / f"s{i}"
            reader = Reader(store)
            reader.start()
            proc = start([sys.executable, "-m", "cclogfs", "record", "ros1://", "--store", str(store),
                          "--sync-ms", "20", "--window-max-s", "0.3", "--budget", "100KiB",
                          "--age-older-than", "1s", "--age-error", "1e-3"], master,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
            try:
                wait_for(lambda: (store / "MANIFEST").exists(), 60, "the live store")  # noqa: B023
                time.sleep(rng.uniform(0.2, 2.5))
                assert proc.poll() is None, "the recorder stopped before it was killed"
                proc.kill()
                assert proc.wait() == -9
            finally:
                proc.kill()
                proc.wait()
                reader.stop.set()
                reader.join()
            reads += reader.reads
            check_after_kill(store, reader.seen)
    finally:
        stop(player)
    assert reads > 0, "the reader never saw a window: the kills tested nothing synced"
