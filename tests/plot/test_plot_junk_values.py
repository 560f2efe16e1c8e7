"""Poses with NaN, infinite or absurd values (any JSON may be stored) are left out of the
plots, and stderr says how many: a position of 1e308 next to -1e308 ended `cclog plot` in
matplotlib's "Axis limits cannot be NaN or Inf" traceback (found by the attack of l-atk6)."""

import json

import cclogfs
from cclogfs.cli import main
from cclogfs.plot.store import plot_data


def pose(x, vx=0.5):
    return json.dumps({"pose": {"pose": {"position": {"x": x, "y": 0.0, "z": 0.0}}},
                       "twist": {"twist": {"linear": {"x": vx, "y": 0.0, "z": 0.0}}}})  # fmt: skip


def test_junk_poses_are_left_out_and_counted(tmp_path, capsys):
    texts = [pose(0.1 * i) for i in range(40)]
    texts[5], texts[6], texts[7] = pose(1e308), pose(-1e308), pose(1.0, vx=1e308)
    texts[8] = texts[8].replace('"x": 0.8', '"x": NaN')
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", [(i * 10**9, t) for i, t in enumerate(texts)])
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert plot_data(store).undrawn == 4
    assert main(["plot", str(tmp_path / "s"), "--out", str(tmp_path / "p")]) == 0
    assert "4 of 40 messages of /odom left out of the trajectory or speed plot" in capsys.readouterr().err
    assert (tmp_path / "p" / "speed.png").stat().st_size > 0
