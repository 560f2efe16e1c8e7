"""Shared fixtures. Tests that need ../shared/data skip without it, except in CI."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

# tests import their shared helpers (tests/helpers.py) by plain name.
sys.path.insert(0, os.path.dirname(__file__))

SHARED_DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data"


def shared_data_file(name: str) -> Path:
    """Path of a file in ../shared/data; skips the test when absent (fails under CI=true)."""
    path = SHARED_DATA / name
    if not path.exists():
        if os.environ.get("CI") == "true":
            pytest.fail(f"{path} is missing, and CI must not skip tests that need shared data")
        pytest.skip(f"{path} not present")
    return path


@pytest.fixture
def shared_data():
    return shared_data_file


# The columnar codec's two ways to find a shape's value rows, to write their byte planes
# and to join the rows back: the compiled helpers (cclogfs/codecs/_rows.c and _planes.c,
# built by setup.py where a C compiler is), and the re module, numpy and a % template.
# Modules that use this fixture (pytest.mark.usefixtures) run once per way.
@pytest.fixture(scope="module", params=["compiled", "python"])
def row_path(request):
    from cclogfs.codecs import columnar, columns, shapes

    compiled = (shapes._match_rows_c, shapes._match_columns_c, columnar._join_rows_c,
                columns._pack_ints_c, columns._float_planes_c)  # fmt: skip
    if request.param == "compiled" and None in compiled:
        pytest.skip("the compiled helpers cclogfs.codecs._rows and _planes are not built (no C compiler at install)")
    if request.param == "python":
        shapes._match_rows_c = shapes._match_columns_c = columnar._join_rows_c = None
        columns._pack_ints_c = columns._float_planes_c = None
    yield request.param
    (shapes._match_rows_c, shapes._match_columns_c, columnar._join_rows_c,
     columns._pack_ints_c, columns._float_planes_c) = compiled  # fmt: skip


# The JSONL source's two ways to split lines: the compiled splitter
# (cclogfs/ingest/_jsonl_split.c, built by setup.py where a C compiler is) and Python.
# Modules that use this fixture (pytest.mark.usefixtures) run once per way.
@pytest.fixture(scope="module", params=["compiled", "python"])
def split_path(request):
    from cclogfs.ingest import jsonl

    try:
        from cclogfs.ingest._jsonl_split import split_lines as compiled
    except ImportError:
        compiled = None
    if request.param == "compiled" and compiled is None:
        pytest.skip("the compiled splitter cclogfs.ingest._jsonl_split is not built (no C compiler at install)")
    jsonl._split_lines_c = compiled if request.param == "compiled" else None
    yield request.param
    jsonl._split_lines_c = compiled


@pytest.fixture(scope="module")
def halves():
    """The nav2 TurtleBot's /odom cut in two at its middle: train on one, test on the other
    (the classifier's tests)."""
    from cclogfs.classifier import parse_odometry
    from cclogfs.classifier.testing import read_odometry

    odom = parse_odometry(read_odometry(shared_data_file("nav2_turtlebot.mcap")))
    t = odom.stamp_ns
    mid = t[0] + (t[-1] - t[0]) // 2
    return odom.take(t < mid), odom.take(t >= mid)


@pytest.fixture
def renames_and_fsyncs(monkeypatch):
    """("fsync", file or directory name) and ("replace", destination) of each os.fsync and
    os.replace, in order: whether an output was synced before its rename and its
    directory after."""
    ops: list[tuple[str, str]] = []
    fsync, replace = os.fsync, os.replace

    def logged_fsync(fd):
        ops.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        fsync(fd)

    def logged_replace(a, b):
        ops.append(("replace", str(b)))
        replace(a, b)

    monkeypatch.setattr(os, "fsync", logged_fsync)
    monkeypatch.setattr(os, "replace", logged_replace)
    return ops
