"""Run a benchmark module: `python -m bench NAME [ARGS]`, or list them with no arguments."""

import importlib
import pkgutil
import sys
from pathlib import Path

names = sorted(m.name for m in pkgutil.iter_modules([str(Path(__file__).parent)]) if not m.name.startswith("_"))
if len(sys.argv) < 2 or sys.argv[1] not in names:
    print("usage: python -m bench NAME [ARGS]\nbenchmarks: " + ", ".join(names))
    sys.exit(2)
sys.argv = [f"bench.{sys.argv[1]}", *sys.argv[2:]]
sys.exit(importlib.import_module(f"bench.{sys.argv[0][6:]}").main())
