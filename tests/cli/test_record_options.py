"""`cclog record` option values that cannot work are refused in the option's own words before
anything is read or stored (found by the attack of l-atk8)."""

import pytest

from cclogfs.cli import main

LINE = '{"topic": "/a", "stamp_ns": 1, "msg": {"i": 1}}\n'


@pytest.mark.parametrize("value", ["0", "-1"])
def test_chunk_below_one_is_refused_without_a_traceback(tmp_path, capsys, value):
    # was: ValueError traceback from KeepAll, exit 1 with no `cclog: error:` line
    (tmp_path / "in.jsonl").write_text(LINE)
    assert main(["record", str(tmp_path / "in.jsonl"), "--store", str(tmp_path / "s"), "--chunk", value]) == 1
    err = capsys.readouterr().err
    assert err.startswith("cclog: error: --chunk must be at least 1") and "Traceback" not in err, err
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("value", ["nan", "inf", "1e300", "-1"])
def test_sync_ms_that_no_timer_can_wait_is_refused(tmp_path, capsys, value):
    # was: nan spun the group-commit thread at full CPU while idle; inf and 1e300 killed it
    # with an OverflowError traceback, so nothing was committed on time, exit 0
    (tmp_path / "in.jsonl").write_text(LINE)
    assert main(["record", str(tmp_path / "in.jsonl"), "--store", str(tmp_path / "s"), "--sync-ms", value]) == 1
    err = capsys.readouterr().err
    assert err.startswith("cclog: error: --sync-ms must be") and f"not {float(value)}" in err, err
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("option", ["--before", "--after"])
@pytest.mark.parametrize("value", ["nans", "infs"])
def test_window_extent_that_is_not_finite_is_refused(tmp_path, capsys, option, value):
    # was: a ValueError (nans) or OverflowError (infs) traceback once the model was loaded
    (tmp_path / "in.jsonl").write_text(LINE)
    assert main(["record", str(tmp_path / "in.jsonl"), "--store", str(tmp_path / "s"), "--model",
                 str(tmp_path / "no-model"), option, value]) == 1  # fmt: skip
    err = capsys.readouterr().err
    assert err.startswith(f"cclog: error: window extent '{value}'") and "Traceback" not in err, err


@pytest.mark.parametrize("options, said", [
    (["--before", "4s"], "--before goes with --model"),
    (["--after", "20"], "--after goes with --model"),
    (["--no-summary"], "--no-summary goes with --model"),
    (["--force-model"], "--force-model goes with --model"),
    (["--odom-topic", "/odom"], "--odom-topic goes with --model or --features-out"),
    (["--features", "paper"], "--features goes with --features-out"),
    (["--chunk", "10", "--model", "m"], "--chunk goes without --model"),
])  # fmt: skip
def test_an_option_without_the_one_it_goes_with_is_refused(tmp_path, capsys, options, said):
    # was: recorded every message (or the smart windows, for --chunk), exit 0, the option
    # ignored without a word, as play's --clock without --to ros1:// was
    (tmp_path / "in.jsonl").write_text(LINE)
    assert main(["record", str(tmp_path / "in.jsonl"), "--store", str(tmp_path / "s"), *options]) == 1
    assert capsys.readouterr().err.startswith(f"cclog: error: {said}")
    assert not (tmp_path / "s").exists()
