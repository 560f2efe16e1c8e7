"""Issue 12 item 3: a model that does not fit the source says so; --odom-topic maps the
topic; a robot unlike the training one is refused (or warned with --force-model); pose-only
robots can be modelled (twist from poses)."""

import json
import math

import numpy as np
import pytest

import cclogfs
from cclogfs.classifier import parse_odometry
from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line
from cclogfs.pipeline import read_topic
from conftest import shared_data_file


def write(path, topic, pairs):
    path.write_text("".join(format_line(topic, s, t) for s, t in pairs))
    return str(path)


@pytest.fixture(scope="module")
def odom():
    return read_topic(str(shared_data_file("nav2_turtlebot.mcap")), "/odom")


@pytest.fixture(scope="module")
def model(odom, tmp_path_factory):
    d = tmp_path_factory.mktemp("m")
    src = write(d / "train.jsonl", "/odom", odom[: len(odom) // 2])
    assert main(["train", src, "--out", str(d / "model")]) == 0
    return str(d / "model")


def test_model_keeps_training_statistics(model):
    training = json.loads(open(f"{model}/model.json").read())["training"]
    assert 10 < training["rate_hz"] < 100 and 0 < training["speed_p95"] < 1


def test_record_and_eval_refuse_a_source_without_the_models_topic(tmp_path, capsys, model, odom):
    src = write(tmp_path / "b.jsonl", "/robot/odom", odom[len(odom) // 2:])
    labels = tmp_path / "l.json"
    labels.write_text('{"events": []}')
    for argv in (["record", src, "--store", str(tmp_path / "s"), "--model", model],
                 ["eval", src, "--model", model, "--labels", str(labels)]):  # fmt: skip
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert "no topic /odom" in err and "/robot/odom" in err and "--odom-topic" in err
    assert not (tmp_path / "s").exists()
    assert main(["record", src, "--store", str(tmp_path / "s"), "--model", model, "--odom-topic", "/robot/odom"]) == 0
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert "/cclog/summary" in store.streams()  # it was scored
    assert main(["eval", src, "--model", model, "--labels", str(labels), "--odom-topic", "/robot/odom"]) == 0
    assert "nan" not in capsys.readouterr().out


def test_a_robot_far_from_the_training_one_is_refused_unless_forced(tmp_path, capsys, model, odom):
    fast = []
    for s, text in odom[len(odom) // 2:]:
        m = json.loads(text)
        for k in "xyz":
            m["twist"]["twist"]["linear"][k] *= 10
        fast.append((s, json.dumps(m)))
    src = write(tmp_path / "fast.jsonl", "/odom", fast)
    assert main(["record", src, "--store", str(tmp_path / "s"), "--model", model]) == 1
    err = capsys.readouterr().err
    assert "95th percentile speed" in err and "--force-model" in err and not (tmp_path / "s").exists()
    assert main(["record", src, "--store", str(tmp_path / "s"), "--model", model, "--force-model"]) == 0
    assert "warning: model" in capsys.readouterr().err


def test_an_old_model_without_statistics_still_loads(tmp_path, model, odom):
    old = tmp_path / "old"
    old.mkdir()
    header = json.loads(open(f"{model}/model.json").read())
    del header["training"]
    (old / "model.json").write_text(json.dumps(header))
    (old / "model.npz").write_bytes(open(f"{model}/model.npz", "rb").read())
    src = write(tmp_path / "b.jsonl", "/odom", odom[len(odom) // 2:])
    assert main(["record", src, "--store", str(tmp_path / "s"), "--model", str(old)]) == 0


def pose_messages(odom, kind):
    out = []
    for s, text in odom:
        m = json.loads(text)
        pose, header = m["pose"]["pose"], m["header"]
        if kind == "PoseStamped":
            msg = {"header": header, "pose": pose}
        elif kind == "PoseWithCovarianceStamped":
            msg = {"header": header, "pose": m["pose"]}
        else:
            msg = {"header": header, "child_frame_id": "base", "transform": {
                "translation": pose["position"], "rotation": pose["orientation"]}}
        out.append((s, json.dumps(msg)))
    return out


@pytest.mark.parametrize("kind", ["PoseStamped", "PoseWithCovarianceStamped", "TransformStamped"])
def test_pose_only_robots_get_twist_from_poses_and_can_be_modelled(tmp_path, capsys, odom, kind):
    poses = pose_messages(odom, kind)
    real, derived = parse_odometry(t for _, t in odom), parse_odometry(t for _, t in poses)
    assert np.allclose(real.raw[:, :7], derived.raw[:, :7])
    # The derived forward speed follows the reported one (odometry's own twist is filtered).
    err = np.abs(real.raw[1:, 7] - derived.raw[1:, 7])
    assert np.median(err) < 0.02 and np.percentile(np.abs(derived.raw[1:, 12] - real.raw[1:, 12]), 50) < 0.05
    src = write(tmp_path / "p.jsonl", "/pose", poses[: len(poses) // 2])
    assert main(["train", src, "--topic", "/pose", "--out", str(tmp_path / "m")]) == 0
    rest = write(tmp_path / "r.jsonl", "/pose", poses[len(poses) // 2:])
    assert main(["record", rest, "--store", str(tmp_path / "s"), "--model", str(tmp_path / "m")]) == 0
    assert not math.isnan(json.loads((tmp_path / "m" / "model.json").read_text())["training"]["speed_p95"])


def test_train_refuses_odometry_of_a_robot_standing_still(tmp_path, capsys, odom):
    """l-left8: `cclog train` took the first 3 s of a run (the robot not yet moving) and
    `record --model` then refused the same robot driving ("95th percentile speed 0.714 m/s
    against 0.000505 m/s in training"). Train says so, naming the speed a model needs."""
    still = []
    for s, text in odom[:600]:
        m = json.loads(text)
        for k in "xyz":
            m["twist"]["twist"]["linear"][k] = 0.0
        still.append((s, json.dumps(m)))
    src = write(tmp_path / "still.jsonl", "/odom", still)
    assert main(["train", src, "--out", str(tmp_path / "m")]) == 1
    err = capsys.readouterr().err
    assert "shows a robot standing still: its 95th percentile speed is 0 m/s, under the 0.05 m/s a model needs" in err
    assert "Traceback" not in err and not (tmp_path / "m").exists()
    # The simulator's first 3 s, as found: the robot starts from rest.
    assert main(["simulate", "--out", str(tmp_path / "sim"), "--duration", "3", "--nominal"]) == 0
    assert main(["train", str(tmp_path / "sim" / "run.jsonl"), "--out", str(tmp_path / "m")]) == 1
    assert "standing still" in capsys.readouterr().err
