#!/usr/bin/env python3
"""Set up the project in ./.venv (only Python 3.11 and pip needed), then run a job.

    python3 dev.py demo     # the whole pipeline on simulated robot runs
    python3 dev.py test     # the test suite
    python3 dev.py bench    # benchmarks in bench/
    python3 dev.py cclog ARGS...   # the CLI inside the venv
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
PY = BIN / "python"


def setup(extras: str = "test") -> None:
    """Create the venv and (re)install the project when pyproject.toml or the extras changed."""
    if not PY.exists():
        print("dev.py: creating .venv", flush=True)
        venv.EnvBuilder(with_pip=True).create(VENV)
    stamp = VENV / f".cclogfs-installed-{extras}"
    # Also the compiled helper's source and build: an edit rebuilds it (setup.py).
    built_from = ("pyproject.toml", "setup.py", "cclogfs/codecs/_rows.c", "cclogfs/ingest/_jsonl_split.c",
                  "cclogfs/classifier/_odomtext.c", "cclogfs/classifier/_stream.c")
    want = hashlib.sha256(b"".join((ROOT / name).read_bytes() for name in built_from)).hexdigest()
    if stamp.exists() and stamp.read_text() == want:
        return
    print(f"dev.py: installing cclogfs[{extras}] and its dependencies into .venv", flush=True)
    pip = [str(PY), "-m", "pip", "install", "--disable-pip-version-check", "-q"]
    subprocess.run([*pip, "-e", f"{ROOT}[{extras}]"], check=True)
    stamp.write_text(want)


def run(args: list[str]) -> int:
    return subprocess.run(args, cwd=ROOT).returncode


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in {"demo", "test", "bench", "cclog"}:
        print(__doc__, file=sys.stderr)
        return 2
    job, rest = argv[0], argv[1:]
    setup("test,bench" if job == "bench" else "test")
    if job == "demo":
        return run([str(BIN / "cclog"), "demo", *rest])
    if job == "test":
        return run([str(PY), "-m", "pytest", "-q", "-n", "2", *rest])
    if job == "bench":
        return run([str(PY), "-m", "bench", *rest])
    return run([str(BIN / "cclog"), *rest])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
