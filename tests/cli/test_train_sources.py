"""`cclog train` refuses one run given twice: as two sources its messages were trained on
twice ("60,000 messages from 2 run(s)" of a 30,000-message run), and as --validate the
Table 1 printed was scored on the training data itself, both exit 0 (found by the attack
of l-atk8). Same content under another name counts, as `record` judges a source again."""

import shutil

import pytest

from cclogfs.cli import main
from cclogfs.sim import simulate


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("runs")
    for seed in (1, 2):
        simulate(seed=seed, duration_s=20.0, rate_hz=50.0).write(d / f"r{seed}")
    shutil.copy(d / "r1" / "run.jsonl", d / "copy.jsonl")
    return d


@pytest.mark.parametrize("second", ["r1/run.jsonl", "copy.jsonl"])
def test_a_run_given_twice_is_refused(runs, tmp_path, capsys, second):
    assert main(["train", str(runs / "r1/run.jsonl"), str(runs / second), "--out", str(tmp_path / "m")]) == 1
    err = capsys.readouterr().err
    assert "same content" in err and "twice" in err, err
    assert not (tmp_path / "m").exists()


def test_validating_on_a_training_run_is_refused(runs, tmp_path, capsys):
    assert main(["train", str(runs / "r1/run.jsonl"), "--out", str(tmp_path / "m"), "--validate",
                 str(runs / "copy.jsonl"), "--validate-labels", str(runs / "r1/labels.json")]) == 1  # fmt: skip
    err = capsys.readouterr().err
    assert "--validate" in err and "same content" in err, err
    assert not (tmp_path / "m").exists()
    # a disjoint run validates
    assert main(["train", str(runs / "r1/run.jsonl"), "--out", str(tmp_path / "m"), "--validate",
                 str(runs / "r2/run.jsonl"), "--validate-labels", str(runs / "r2/labels.json")]) == 0  # fmt: skip
