"""Classifier speed: training time and memory on 10,000 vectors, live scoring latency per
message (p50/p99), batch replay throughput. Run: python bench/classifier_speed.py"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cclogfs.classifier.api import Detector, SmartLogger, train  # noqa: E402
from cclogfs.classifier.features import make_features, parse_odometry  # noqa: E402
from cclogfs.classifier.testing import odom_texts, read_odometry, resample  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "nav2_turtlebot.mcap"

TRAIN_CHILD = """
import sys, time, resource, numpy as np
sys.path.insert(0, {root!r})
from cclogfs.classifier.model import OneClassModel
from cclogfs.classifier.api import DEFAULT_FLOORS
X = np.load({path!r})
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
m = OneClassModel(min_scale=DEFAULT_FLOORS, one_sided=True).fit(X)
dt = time.perf_counter() - t0
print(dt, base / 1024, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, len(m.dual_coef_))
"""


def main() -> None:
    odom = parse_odometry(read_odometry(DATA))
    run100 = resample(odom, 100, jitter_s=0.002)  # 9,500 messages at 100 Hz
    fs = make_features("default")
    X, valid = fs.batch(run100)
    X = np.concatenate([X[valid], X[valid][:1000]])[:10_000]
    path = Path("/tmp/cclog_bench_X.npy")
    np.save(path, X)
    out = subprocess.run([sys.executable, "-c", TRAIN_CHILD.format(root=str(ROOT), path=str(path))],
                         capture_output=True, text=True, check=True).stdout.split()
    print(f"train on {len(X)} vectors: {float(out[0]):.2f} s, peak RSS {float(out[2]):.0f} MB "
          f"(after imports+data {float(out[1]):.0f} MB), {out[3]} support vectors  [target < 2 s, < 300 MB]")

    model = train([run100])
    texts = odom_texts(run100)
    det = Detector(model)
    lat = []
    for text in texts:
        t0 = time.perf_counter()
        det.update(text)
        lat.append(time.perf_counter() - t0)
    lat = np.array(lat[200:]) * 1e3
    print(f"live score per message (parse+features+SVM), 100 Hz run: p50 {np.median(lat):.3f} ms, "
          f"p99 {np.percentile(lat, 99):.3f} ms  [target p99 < 1 ms]")

    reps = 5
    big = [t for _ in range(reps) for t in texts]
    stamps = np.concatenate([run100.stamp_ns + i * 10**12 for i in range(reps)])
    t0 = time.perf_counter()
    parsed = parse_odometry(big)
    t_parse = time.perf_counter() - t0
    t0 = time.perf_counter()
    Detector(model).score_batch(parsed)
    t_score = time.perf_counter() - t0
    stream = [("/odom", int(s), x) for s, x in zip(stamps, big)]
    t0 = time.perf_counter()
    SmartLogger(Detector(model), before_s=4, after_s=4).replay(stream)
    t_all = time.perf_counter() - t0
    n = len(big)
    print(f"batch replay of {n} messages: parse {n / t_parse:,.0f} msg/s, features+score "
          f"{n / t_score:,.0f} msg/s, whole SmartLogger.replay {n / t_all:,.0f} msg/s  "
          f"[target >= 50,000 msg/s]")


if __name__ == "__main__":
    main()
