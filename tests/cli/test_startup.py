"""Start-up: `cclog --help` loads no engine, and each subcommand only what it runs on.

A one-second `cclog cat` was mostly imports (pyarrow, rosbags, the classifier); these
tests hold each command to the packages it needs, in a fresh interpreter.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

HEAVY = ["numpy", "pyarrow", "rosbags", "mcap", "sklearn", "zstandard", "cclogfs.store", "cclogfs.classifier",
         "cclogfs.ingest", "cclogfs.export.parquet", "cclogfs.export.mcap", "cclogfs.sim", "cclogfs.pipeline"]  # fmt: skip

PROBE = """
import json, sys
from cclogfs.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
heavy = json.loads(sys.stdin.read())
print(json.dumps(sorted(h for h in heavy if h in sys.modules)), file=sys.stderr)
"""


def loaded(*argv: str, modules: list[str] = HEAVY) -> set[str]:
    """The `modules` (HEAVY) in sys.modules after `cclog ARGV` ran in a fresh interpreter."""
    out = subprocess.run([sys.executable, "-c", PROBE, *argv], input=json.dumps(modules), capture_output=True,
                         text=True, timeout=120)  # fmt: skip
    return set(json.loads(out.stderr.strip().splitlines()[-1]))


def test_help_loads_nothing_heavy():
    assert loaded("--help") == set()


def test_help_loads_no_subcommand():
    """Issue 14, tenth pass: `cclog --help` imported all 13 subcommand modules for their
    help lines and, through them, dataclasses, inspect, secrets and datetime (0.58x CPU
    without); the lines live in cli.COMMANDS."""
    from cclogfs.cli import COMMANDS

    modules = [f"cclogfs.cli.{name}" for name in COMMANDS] + ["dataclasses", "inspect", "secrets"]
    assert loaded("--help", modules=modules) == set()
    assert loaded("cat", "--help", modules=modules) >= {"cclogfs.cli.cat"}


def test_cat_loads_the_store_and_no_exporter_or_source(tmp_path):
    from cclogfs.store import open_store

    with open_store(tmp_path / "s", create=True) as store:
        # Varying floats, ints and a quaternion: the columnar codec's float, int and
        # quaternion columns are read back.
        store.put_window("/odom", [(i, json.dumps({"x": 1.5 + i / 7, "n": i, "q": [0.0, 0.0, math.sin(i / 9),
                                                                                   math.cos(i / 9)]}))
                                   for i in range(40)])  # fmt: skip
    got = loaded("cat", str(tmp_path / "s"))
    assert "cclogfs.store" in got
    # numpy too (issue 14): its import cost `cat` of one second more than the rest together;
    # the index and the columnar decoder are plain Python.
    assert not got & {"numpy", "pyarrow", "rosbags", "mcap", "sklearn", "cclogfs.classifier", "cclogfs.ingest",
                      "cclogfs.export.parquet", "cclogfs.export.mcap", "cclogfs.sim", "cclogfs.pipeline"}
    # Nor what it never uses: simdjson (cat checks no JSON) and secrets (a work file's name).
    assert not loaded("cat", str(tmp_path / "s"), modules=["simdjson", "secrets"])


def test_ctrl_c_while_loading_a_command_is_interrupted_not_a_traceback(monkeypatch, capsys):
    """A Ctrl-C in the first half second (found by attack: /tmp/atk3/sigint.py, SIGINT 0.15 s
    after starting `cclog record`) printed a KeyboardInterrupt traceback from the import."""
    import importlib

    from cclogfs.cli import main

    def interrupted(name, *args):
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib, "import_module", interrupted)
    assert main(["record", "x.jsonl", "--store", "s"]) == 130
    assert capsys.readouterr().err == "cclog: interrupted\n"


def test_info_loads_the_store_and_not_the_classifier(tmp_path):
    """l-left8: info imported the classifier (and numpy, a quarter second of CPU) for the
    name of the summary stream; it reads the store alone."""
    from cclogfs.store import open_store

    with open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", [(i, json.dumps({"x": i / 7})) for i in range(40)])
        store.put_window("/cclog/summary", [(0, json.dumps({"messages": 40, "distance_m": 1.5}))], meta={"kind": "summary"})
    got = loaded("info", str(tmp_path / "s"))
    assert "cclogfs.store" in got
    assert not got & {"numpy", "pyarrow", "rosbags", "mcap", "sklearn", "cclogfs.classifier", "cclogfs.ingest"}
