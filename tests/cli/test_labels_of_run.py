"""Labels that cannot be the run's are refused, not scored as every event missed (or
trained on as nominal) with exit 0: an event ending before it starts, and an event wholly
outside the run's odometry (labels of another run, or in another clock). Found by the
attack of l-atk6."""

import json

import pytest

from cclogfs.cli import main
from cclogfs.sim import simulate


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("runs")
    simulate(seed=5, duration_s=30.0, rate_hz=50.0).write(d / "nominal")
    simulate(seed=6, duration_s=60.0, rate_hz=50.0, anomalies=2).write(d / "test")
    assert main(["train", str(d / "nominal" / "run.jsonl"), "--out", str(d / "model")]) == 0
    return d


def labels(path, *events):
    path.write_text(json.dumps({"events": [{"start_ns": a, "end_ns": b, "kind": "spin"} for a, b in events]}))
    return str(path)


def test_eval_refuses_labels_of_another_run_and_reversed_events(runs, tmp_path, capsys):
    real = json.loads((runs / "test" / "labels.json").read_text())["events"]
    start, end = real[0]["start_ns"], real[0]["end_ns"]
    src, model = str(runs / "test" / "run.jsonl"), str(runs / "model")
    cases = {"outside": labels(tmp_path / "o.json", (1, 5)), "reversed": labels(tmp_path / "r.json", (end, start))}
    for name, path in cases.items():
        assert main(["eval", src, "--model", model, "--labels", path]) == 1, name
        err = capsys.readouterr().err
        assert f"labels {path}: event 1" in err and err.count("\n") == 1, err
    assert main(["eval", src, "--model", model, "--labels", str(runs / "test" / "labels.json")]) == 0


def test_train_refuses_labels_outside_its_run(runs, tmp_path, capsys):
    out = tmp_path / "m"
    later = labels(tmp_path / "later.json", (1 << 62, (1 << 62) + 10**9))
    assert main(["train", str(runs / "test" / "run.jsonl"), "--labels", later, "--out", str(out)]) == 1
    assert "lies outside" in capsys.readouterr().err and not out.exists()
    assert main(["train", str(runs / "nominal" / "run.jsonl"), "--out", str(out), "--validate",
                 str(runs / "test" / "run.jsonl"), "--validate-labels", later]) == 1  # fmt: skip
    assert "lies outside" in capsys.readouterr().err and not out.exists()  # refused before training

