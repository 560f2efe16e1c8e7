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
