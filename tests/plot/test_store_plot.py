"""`cclog plot`: the values drawn come from the store, and the PNG files are real images."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from cclogfs import open_store
from cclogfs.plot.store import plot_data
from cclogfs.runs import hidden_by_default

CCLOG = [sys.executable, "-m", "cclogfs"]


def cclog(*args):
    return subprocess.run([*CCLOG, *map(str, args)], check=True, capture_output=True, text=True)


@pytest.fixture(scope="module")
def smart_store(tmp_path_factory):
    d = tmp_path_factory.mktemp("plot")
    cclog("simulate", "--seed", 1, "--duration", 120, "--anomalies", 2, "--rate", 20, "--robot-seed", 1, "--out", d / "run")
    cclog("simulate", "--seed", 2, "--duration", 90, "--nominal", "--rate", 20, "--robot-seed", 1, "--out", d / "nom")
    cclog("train", d / "nom" / "run", "--out", d / "model")
    cclog("record", d / "run" / "run", "--store", d / "s", "--model", d / "model", "--window-max-s", "0.001")
    return d / "s"


def png_shape(path):
    import matplotlib.image

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return matplotlib.image.imread(path).shape


def test_plot_draws_the_stored_odometry_windows_and_scores(smart_store, tmp_path):
    r = cclog("plot", smart_store, "--out", tmp_path / "p")
    paths = sorted(r.stdout.split())
    assert [p.rsplit("/", 1)[1] for p in paths] == ["speed.png", "trajectory.png", "windows.png"]
    for p in paths:
        h, w, _ = png_shape(tmp_path / "p" / p.rsplit("/", 1)[1])
        assert h >= 100 and w >= 800
        assert (tmp_path / "p" / p.rsplit("/", 1)[1]).stat().st_size > 10_000  # drawn, not blank
    with open_store(smart_store, readonly=True) as store:
        data = plot_data(store)
        odom = [(s, json.loads(t)) for w in store.query("/odom") for s, t in w.messages()]
        spans = {n: [(w.start_ns, w.end_ns) for w in store.query(n)] for n in store.streams() if not hidden_by_default(n)}
        metas = [w.meta for w in store.query("/odom")]
        summary = [json.loads(t) for w in store.query("/cclog/summary") for _, t in w.messages()]
    assert data.topic == "/odom" and len(odom) == len(data.x) > 0
    assert data.stamp_ns.tolist() == [s for s, _ in odom]
    assert data.x.tolist() == [m["pose"]["pose"]["position"]["x"] for _, m in odom]
    assert data.y.tolist() == [m["pose"]["pose"]["position"]["y"] for _, m in odom]
    lin = [m["twist"]["twist"]["linear"] for _, m in odom]
    assert np.allclose(data.speed, [math.hypot(v["x"], v["y"]) for v in lin])
    assert data.windows == spans and len(spans["/odom"]) >= 1
    finals = {m["window_id"]: (m["peak_ns"], m["peak_score"]) for m in metas}
    assert data.counted["/odom"] == len(finals) < len(metas)  # the trajectory's title: a window's parts once
    assert data.peaks == sorted(finals.values()) and all(s > 0 for _, s in data.peaks)
    assert data.summary == sorted((s["start_ns"], s["end_ns"], s["anomalies"]) for s in summary)
    assert sum(n for *_, n in data.summary) > 0


def test_plot_of_a_store_without_poses_draws_its_windows_only(shared_data, tmp_path):
    cclog("record", shared_data("tf_example.bag"), "--store", tmp_path / "s")
    r = cclog("plot", tmp_path / "s", "--out", tmp_path / "p")
    assert r.stdout.split() == [str(tmp_path / "p" / "windows.png")] and "no pose stream" in r.stderr
    assert png_shape(tmp_path / "p" / "windows.png")[1] >= 800


def test_plot_of_poses_without_twist_differentiates_them(shared_data, tmp_path):
    cclog("record", shared_data("nav2_turtlebot.mcap"), "--store", tmp_path / "s", "--topic", "/amcl_pose")
    cclog("plot", tmp_path / "s", "--out", tmp_path / "p")  # found by its type, PoseWithCovarianceStamped
    with open_store(tmp_path / "s", readonly=True) as store:
        data = plot_data(store)
    assert data.topic == "/amcl_pose" and len(data.x) == 135
    dt = (data.stamp_ns[5] - data.stamp_ns[4]) / 1e9
    assert math.isclose(data.speed[5], math.hypot(data.x[5] - data.x[4], data.y[5] - data.y[4]) / dt)
    r = subprocess.run([*CCLOG, "plot", str(tmp_path / "s"), "--topic", "/nope"], capture_output=True, text=True)
    assert r.returncode == 1 and "no stream /nope" in r.stderr


def run_cclog(*args):
    return subprocess.run([*CCLOG, *map(str, args)], capture_output=True, text=True)


def test_plot_errors_are_one_line_naming_what_is_wrong(tmp_path):
    # --out onto a file was FileExistsError's traceback; an empty store gave an empty
    # windows.png and exit 0; a pose-less /odom (the golden store's) did not say where.
    with open_store(tmp_path / "empty", create=True):
        pass
    with open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", [(5, json.dumps({"v": 1}))])
        store.put_window("/list", [(7, "[1, 2]")])
    (tmp_path / "afile").write_text("x")
    cases = [(["plot", tmp_path / "s", "--topic", "/odom", "--out", tmp_path / "afile"], "afile"),
             (["plot", tmp_path / "empty", "--out", tmp_path / "p"], "no messages"),
             (["plot", tmp_path / "s", "--out", tmp_path / "p"], "/odom at 5 ns"),
             (["plot", tmp_path / "s", "--topic", "/list", "--out", tmp_path / "p"], "/list at 7 ns")]
    for args, said in cases:
        r = run_cclog(*args)
        assert r.returncode == 1 and r.stderr.startswith("cclog: error: ") and r.stderr.count("\n") == 1, r.stderr
        assert said in r.stderr, r.stderr
    assert (tmp_path / "afile").read_text() == "x" and not (tmp_path / "p").exists()
