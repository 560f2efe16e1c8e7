"""Issue 12 item 1: inputs are never written; outputs appear whole or not at all; --force."""

import json
import os
import subprocess
import sys

import pytest

import cclogfs
from cclogfs.cli import main


def jsonl(path, n=5):
    path.write_text("".join(json.dumps({"topic": "/odom", "stamp_ns": i, "msg": {"i": i}}) + "\n" for i in range(n)))
    return path.read_bytes()


@pytest.mark.parametrize("how", ["same", "hardlink", "symlink"])
def test_convert_refuses_its_input_as_output(tmp_path, capsys, how):
    src = tmp_path / "in.jsonl"
    before = jsonl(src)
    out = src
    if how == "hardlink":
        out = tmp_path / "link.jsonl"
        os.link(src, out)
    elif how == "symlink":
        out = tmp_path / "sym.jsonl"
        out.symlink_to(src)
    for extra in ([], ["--force"]):
        assert main(["convert", str(src), "-o", str(out), *extra]) == 1
        assert "is the input" in capsys.readouterr().err
    assert src.read_bytes() == before


def test_convert_needs_force_to_replace_and_leaves_no_temp_file(tmp_path, capsys):
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    data = jsonl(src)
    out.write_text("keep me\n")
    assert main(["convert", str(src), "-o", str(out)]) == 1
    assert "--force" in capsys.readouterr().err and out.read_text() == "keep me\n"
    assert main(["convert", str(src), "-o", str(out), "--force"]) == 0
    assert out.read_bytes() == data
    bad = tmp_path / "bad.jsonl"
    bad.write_bytes(data + b"{not json\n")
    assert main(["convert", str(bad), "-o", str(out), "--force"]) == 1  # fails half way
    assert out.read_bytes() == data  # the old output stays whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.jsonl", "in.jsonl", "out.jsonl"]


def test_export_mcap_and_parquet_need_force(tmp_path, capsys):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", [(1, '{"x": 1}'), (2, '{"x": 2}')])
    mcap = tmp_path / "o.mcap"
    mcap.write_bytes(b"old")
    assert main(["export", str(tmp_path / "s"), "--mcap", str(mcap)]) == 1
    assert "--force" in capsys.readouterr().err and mcap.read_bytes() == b"old"
    assert main(["export", str(tmp_path / "s"), "--mcap", str(mcap), "--force"]) == 0
    assert mcap.read_bytes()[:8] == b"\x89MCAP0\r\n"
    lake = tmp_path / "lake"
    assert main(["export", str(tmp_path / "s"), "--parquet", str(lake)]) == 0
    assert main(["export", str(tmp_path / "s"), "--parquet", str(lake)]) == 1
    assert "--force" in capsys.readouterr().err
    for flag in ("--force", "--replace"):
        assert main(["export", str(tmp_path / "s"), "--parquet", str(lake), flag]) == 0


def test_export_refuses_an_output_inside_the_store(tmp_path, capsys):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", [(1, '{"x": 1}')])
    assert main(["export", str(tmp_path / "s"), "--mcap", str(tmp_path / "s" / "x.mcap")]) == 1
    assert "is the input" in capsys.readouterr().err


def test_convert_output_gets_the_mode_a_new_file_gets(tmp_path, capsys):
    """It was written under mkstemp's 0600 and renamed into place: an output others could
    not read, and --force took an existing output's mode away too."""
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    jsonl(src)
    old = os.umask(0o022)
    try:
        assert main(["convert", str(src), "-o", str(out)]) == 0
    finally:
        os.umask(old)
    assert os.stat(out).st_mode & 0o777 == 0o644
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.jsonl", "out.jsonl"]


def test_convert_syncs_its_output_before_the_rename_and_the_directory_after(tmp_path, renames_and_fsyncs):
    """Found by attack: convert renamed its work file into place unsynced, so a power cut
    could leave an empty or partial file under the final name."""
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    jsonl(src)
    ops = renames_and_fsyncs
    assert main(["convert", str(src), "-o", str(out)]) == 0
    at = ops.index(("replace", str(out)))
    assert any(op == "fsync" and os.path.basename(p).startswith(".out.jsonl.") for op, p in ops[:at]), ops
    assert ("fsync", str(tmp_path)) in ops[at:], ops


def test_convert_removes_the_work_file_a_killed_convert_left(tmp_path):
    """Found by attack: a convert killed mid-write left its hidden `.OUT.*.tmp` for good."""
    src, out = tmp_path / "in.jsonl", tmp_path / "out.jsonl"
    jsonl(src)
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()  # a pid no process has now: the writer was killed
    (tmp_path / f".out.jsonl.{proc.pid}.0badf00d.tmp").write_text("half a convert")
    assert main(["convert", str(src), "-o", str(out)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.jsonl", "out.jsonl"]
