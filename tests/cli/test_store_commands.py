"""`cclog info` and `cclog fsck` through the CLI entry point."""

import json
import shutil
from pathlib import Path

import cclogfs
from cclogfs.cli import main
from helpers import flip


def build(path, n=60):
    with cclogfs.open_store(path, create=True, segment_bytes=4096, sync_every_bytes=1) as store:
        for i in range(n):
            store.put_window("/odom" if i % 3 else "/tf", [(i * 100 + k, json.dumps({"i": i, "k": k})) for k in range(10)])


def test_info_json_matches_store(tmp_path, capsys):
    build(tmp_path / "s")
    assert main(["info", str(tmp_path / "s"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["streams"]["/odom"]["windows"] == 40 and info["streams"]["/tf"]["messages"] == 200
    assert info["streams"]["/odom"]["codec"]["id"] == "columnar"  # the default codec
    assert main(["info", str(tmp_path / "s")]) == 0
    assert "/odom" in capsys.readouterr().out


def test_fsck_clean_then_damaged(tmp_path, capsys):
    build(tmp_path / "s")
    assert main(["fsck", str(tmp_path / "s"), "--deep"]) == 0
    out = capsys.readouterr().out
    assert "clean" in out and "60 records" in out and "60 windows decoded" in out
    seg = tmp_path / "s" / "00000000000000000000.seg"
    flip(seg, 200, 1)
    assert main(["fsck", str(tmp_path / "s")]) == 1
    out = capsys.readouterr().out
    assert "00000000000000000000.seg@" in out and "DAMAGED" in out
    assert "intact and readable through the index" in out


def test_fsck_reports_torn_tail_as_warning(tmp_path, capsys):
    build(tmp_path / "s", n=3)
    with open(tmp_path / "s" / "00000000000000000000.seg", "ab") as f:
        f.write(b"CCLR\x01")
    assert main(["fsck", str(tmp_path / "s")]) == 0
    assert "torn record" in capsys.readouterr().out


def test_errors_are_one_line_and_exit_nonzero(tmp_path, capsys):
    assert main(["info", str(tmp_path / "missing")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("cclog: error:") and "not a cclogfs store" in err and err.count("\n") == 1


def test_info_totals_the_summary_stream(tmp_path, capsys):
    recs = [{"messages": 600, "distance_m": 12.5, "moving_s": 50.0, "anomalies": 3, "peak_speed": 0.9,
             "peak_accel": 1.5}, {"messages": 300, "distance_m": 7.5, "moving_s": 20.0, "anomalies": 0,
             "peak_speed": 1.1, "peak_accel": 0.5}]  # fmt: skip
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        for i, rec in enumerate(recs):
            store.put_window("/cclog/summary", [(i * 60 * 10**9, json.dumps(rec))])
    assert main(["info", str(tmp_path / "s"), "--json"]) == 0
    totals = json.loads(capsys.readouterr().out)["summary"]
    assert totals == {"minutes": 2, "messages": 900, "distance_m": 20.0, "moving_s": 70.0, "anomalies": 3,
                      "peak_speed": 1.1, "peak_accel": 1.5}  # fmt: skip
    assert main(["info", str(tmp_path / "s")]) == 0
    assert "0.020 km driven" in capsys.readouterr().out


def test_info_and_fsck_on_a_compacted_store(tmp_path, capsys):
    # The golden v2 store: the log starts at seq 2, one segment dropped, one AGED window.
    shutil.copytree(Path(__file__).parent.parent / "golden" / "store_v2", tmp_path / "s")
    assert main(["info", str(tmp_path / "s"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["format_version"], info["first_seq"], info["dropped"]["segments"]) == (2, 2, 1)
    assert info["dropped"]["streams"]["/odom"]["windows"] == 2 and info["streams"]["/tf"]["aged"] == 1
    assert main(["info", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "aged: 1 of 3 windows of /tf" in out
    assert "retention dropped 2 windows (12 messages) of /odom from 1970-01-01T00:00:00.000Z" in out
    assert main(["fsck", "--deep", str(tmp_path / "s")]) == 0
    assert "clean" in (out := capsys.readouterr().out) and "1 aged windows" in out


def test_fsck_of_no_store_is_an_operational_error_not_damage(tmp_path, capsys):
    # Issue 12, item 9: `cclog fsck missing.store` printed DAMAGED; nothing to check is not
    # damage. A missing path, a file, or an empty directory: one line on stderr, exit 8.
    from cclogfs.cli import main

    (tmp_path / "afile").write_text("x\n")
    (tmp_path / "empty").mkdir()
    for name, why in [("missing.store", "does not exist"), ("afile", "not a directory"),
                      ("empty", "holds no cclogfs store")]:  # fmt: skip
        assert main(["fsck", str(tmp_path / name)]) == 8
        out, err = capsys.readouterr()
        assert "DAMAGED" not in out and why in err and "\n" not in err.strip(), (out, err)


def test_a_failed_record_leaves_a_store_another_writer_holds(tmp_path):
    """`record` removes a store it created when it fails before storing anything; a store
    another writer created meanwhile, and holds, is not its to remove (two runs creating one
    store at once: the loser deleted the store the winner was writing)."""
    from cclogfs.cli.record import _remove_if_empty

    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True) as held:  # nothing stored yet
        _remove_if_empty(str(path))
        assert (path / "MANIFEST").exists()
        held.put_window("/a", [(1, "{}")])
    _remove_if_empty(str(path))  # not held, but it holds messages
    assert (path / "MANIFEST").exists()
    empty = tmp_path / "e"
    cclogfs.open_store(empty, create=True).close()
    _remove_if_empty(str(empty))  # neither held nor holding messages: a failed run's own
    assert not empty.exists()
