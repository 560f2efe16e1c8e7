"""`cclog play` arguments that used to end in a traceback or play without pacing, and the
no-match error naming a one-sided time range (it said "between 2030-01-01... and None").
Found by the attack of l-atk6."""

from __future__ import annotations

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.play.pace import paced

S = 1_000_000_000


@pytest.fixture()
def store(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True) as s:
        s.put_window("/a", [(10 * S, '{"i": 1}'), (11 * S, '{"i": 2}')])
    return str(tmp_path / "s")


def test_a_tiny_rate_sleeps_instead_of_overflowing_time_sleep():
    now, slept = [0.0], []

    def sleep(s):  # as time.sleep: past ~9.2e9 s, "timestamp out of range for platform time_t"
        if s > 9.2e9:
            raise OverflowError("timestamp out of range for platform time_t")
        slept.append(s)
        now[0] += s

    msgs = [("/a", 0, "{}"), ("/a", 1 * S, "{}")]
    assert [m[1] for m in paced(msgs, rate=1e-10, clock=lambda: now[0], sleep=sleep)] == [0, S]
    assert now[0] == pytest.approx(1e10) and max(slept) <= 86400


@pytest.mark.parametrize("gap", ["nan", "-1", "inf"])
def test_skip_gaps_must_be_a_number_of_seconds(store, capsys, gap):
    assert main(["play", store, "--skip-gaps", gap]) == 1
    err = capsys.readouterr().err
    assert "--skip-gaps must be a number of seconds >= 0" in err and "Traceback" not in err


def test_no_match_names_a_one_sided_range(store, capsys):
    assert main(["cat", store, "--start", "2030-01-01"]) == 1
    err = capsys.readouterr().err
    assert "from 2030-01-01T00:00:00.000Z on" in err and "None" not in err
    assert main(["play", store, "--end", "5s"]) == 1
    err = capsys.readouterr().err
    assert "up to 1970-01-01T00:00:05.000Z" in err and "None" not in err


@pytest.mark.parametrize("opts", [["--clock"], ["--host", "0.0.0.0"], ["--wait-for-subscribers"]])
def test_options_of_another_sink_are_refused_not_ignored(store, capsys, opts):
    assert main(["play", store, *opts]) == 1
    assert "goes with" in capsys.readouterr().err
