"""Issue 11, item 4: every subcommand, given bad paths, fails in one line naming the path,
with a non-zero exit, no traceback and no temporary file left."""

import json
import os

import pytest

from cclogfs.cli import build_parser, main
from helpers import make_store

STORE_KINDS = ["missing", "afile", "adir", "/proc/cclog-unwritable"]  # /proc: unwritable, even for root


def _cases():
    """(argv, the path the error must name) for every subcommand."""
    cases = []
    for st in STORE_KINDS:
        name = os.path.basename(st)
        cases += [(["info", st], name), (["cat", st], name), (["fsck", st, "--repair"], name),
                  (["export", st, "--mcap", "o.mcap"], name), (["compact", st, "--max-rate", "1"], name),
                  (["play", st], name), (["plot", st, "--out", "plots"], name)]  # fmt: skip
    # A missing or empty directory is a store `record` creates: only these are bad for it.
    cases += [(["record", "in.jsonl", "--store", st], os.path.basename(st)) for st in ("afile", STORE_KINDS[-1])]
    cases += [
        (["fsck", "afile"], "afile"),
        (["export", "good", "--mcap", "nodir/o.mcap"], "nodir"),
        (["export", "good", "--mcap", "adir"], "adir"),
        (["export", "good", "--parquet", "afile"], "afile"),
        (["record", "nosuch.jsonl", "--store", "s2"], "nosuch.jsonl"),
        (["convert", "nosuch.jsonl", "-o", "o.jsonl"], "nosuch.jsonl"),
        (["train", "nosuch.jsonl", "--out", "m"], "nosuch.jsonl"),
        (["eval", "nosuch.jsonl", "--model", "m", "--labels", "l.json"], "model m"),  # the model is read first
        (["simulate", "--out", "afile/x", "--nominal", "--duration", "5"], "afile"),
        (["demo", "--out", "afile/x", "--no-plots", "--train-minutes", "0.1", "--test-minutes", "0.1"], "afile"),
        (["plot", "good", "--out", "afile"], "afile"),
    ]
    return cases


def test_the_cases_cover_every_subcommand():
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    argvs = [c.values[0] if hasattr(c, "values") else c[0] for c in _cases()]
    assert set(sub.choices) <= {argv[0] for argv in argvs}


@pytest.mark.parametrize("argv, named", _cases(), ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_bad_paths_fail_in_one_line(tmp_path, monkeypatch, capsys, argv, named):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x\n")
    (tmp_path / "adir").mkdir()
    (tmp_path / "in.jsonl").write_text(json.dumps({"topic": "/a", "stamp_ns": 1, "msg": {"x": 1}}) + "\n")
    make_store(tmp_path / "good", n=2)
    before = set(os.listdir(tmp_path))
    rc = main(argv)  # any exception here is the traceback this test forbids
    err = capsys.readouterr().err.strip()
    assert rc != 0
    if argv[:2] != ["fsck", "afile"]:  # plain fsck prints its finding on stdout
        assert "\n" not in err and named in err, err
    left = [os.path.join(d, f) for d, _, fs in os.walk(tmp_path) for f in fs if ".tmp" in f]
    assert not left
    assert not (set(os.listdir(tmp_path)) - before - {"s2"}) or argv[0] in ("simulate", "demo")
