"""Directory outputs (`train --out`, `plot --out`, `simulate --out`) are never an input nor
inside a store, and `train` replaces an existing model only with --force (found by the
attack of l-atk6: each of these wrote into the store or bag without a word, exit 0)."""

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.sim import simulate


def listing(path):
    return sorted((p.relative_to(path).as_posix(), p.stat().st_size if p.is_file() else -1) for p in path.rglob("*"))


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    simulate(seed=3, duration_s=20.0, rate_hz=50.0).write(d)
    return d


@pytest.fixture()
def store(tmp_path, run_dir):
    assert main(["record", str(run_dir / "run.jsonl"), "--store", str(tmp_path / "s")]) == 0
    return tmp_path / "s"


def test_train_refuses_its_input_bag_directory(tmp_path, run_dir, capsys):
    before = listing(run_dir)
    for extra in ([], ["--force"]):
        assert main(["train", str(run_dir / "run"), "--out", str(run_dir / "run"), *extra]) == 1
        assert "is the input" in capsys.readouterr().err
    assert listing(run_dir) == before


def test_train_refuses_a_store_and_a_directory_inside_one(store, run_dir, capsys):
    before = listing(store)
    for out, extra in ((store, []), (store, ["--force"]), (store / "model", [])):
        assert main(["train", str(run_dir / "run.jsonl"), "--out", str(out), *extra]) == 1
        assert "is a cclogfs store" in capsys.readouterr().err
    assert listing(store) == before


def test_train_replaces_a_model_only_with_force_and_nothing_else_even_so(tmp_path, run_dir, capsys):
    model = tmp_path / "m"
    assert main(["train", str(run_dir / "run.jsonl"), "--out", str(model)]) == 0
    before = listing(model)
    assert main(["train", str(run_dir / "run.jsonl"), "--out", str(model)]) == 1
    assert "--force" in capsys.readouterr().err and listing(model) == before
    assert main(["train", str(run_dir / "run.jsonl"), "--out", str(model), "--force"]) == 0
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "todo.txt").write_text("keep me")
    assert main(["train", str(run_dir / "run.jsonl"), "--out", str(notes), "--force"]) == 1
    assert "not a model directory" in capsys.readouterr().err
    assert [p.name for p in notes.iterdir()] == ["todo.txt"]
    (tmp_path / "empty").mkdir()  # made beforehand, as `mkdir -p models/x` would
    assert main(["train", str(run_dir / "run.jsonl"), "--out", str(tmp_path / "empty")]) == 0


def test_plot_refuses_the_store_and_a_directory_inside_it(store, tmp_path, capsys):
    before = listing(store)
    for out in (store, store / "plots"):
        assert main(["plot", str(store), "--out", str(out)]) == 1
        assert "is the store" in capsys.readouterr().err
    assert listing(store) == before
    assert main(["plot", str(store), "--out", str(tmp_path / "plots")]) == 0
    with cclogfs.open_store(store, readonly=True):  # the store still opens, untouched
        pass


def test_simulate_refuses_a_store_and_contradicting_counts(store, tmp_path, capsys):
    before = listing(store)
    assert main(["simulate", "--duration", "5", "--anomalies", "0", "--out", str(store)]) == 1
    assert "is a cclogfs store" in capsys.readouterr().err and listing(store) == before
    # --nominal (or a Poisson rate) used to win over --anomalies silently: 0 anomalies, exit 0
    for other in (["--nominal"], ["--rate-per-min", "1"]):
        assert main(["simulate", "--duration", "5", "--anomalies", "3", *other, "--out", str(tmp_path / "x")]) == 1
        assert "contradict" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_train_refuses_a_false_alarm_rate_outside_0_to_1(tmp_path, run_dir, capsys):
    for rate in ("nan", "-1", "1.5"):
        assert main(["train", str(run_dir / "run.jsonl"), "--out", str(tmp_path / "m"), "--false-alarm-rate", rate]) == 1
        assert "--false-alarm-rate must be a fraction from 0 to 1" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


def test_demo_refuses_a_store(store, capsys):
    before = listing(store)
    assert main(["demo", "--out", str(store), "--no-plots"]) == 1
    assert "is a cclogfs store" in capsys.readouterr().err and listing(store) == before


@pytest.mark.parametrize("flag", ["--mcap", "--rosbag2", "--parquet"])
def test_export_to_dash_is_refused_not_a_file_named_dash(store, tmp_path, monkeypatch, capsys, flag):
    monkeypatch.chdir(tmp_path)
    assert main(["export", str(store), flag, "-", "--robot", "r"][: 4 if flag != "--parquet" else 6]) == 1
    assert "not standard output" in capsys.readouterr().err and not (tmp_path / "-").exists()
