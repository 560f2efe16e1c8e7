#!/usr/bin/env python3
"""Thin wrapper: `python tools/simulate.py ARGS` is `cclog simulate ARGS`."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from cclogfs.cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["simulate", *sys.argv[1:]]))
