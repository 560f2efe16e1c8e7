"""Coverage-guided fuzzing of every parser with atheris (issue 16, "Fuzzing").

    pip install -e .[fuzz]
    python -m bench fuzz [--seconds 60] [--target index,manifest] [--update-corpus]

Each target of bench/_fuzz_targets.py runs in its own process for `--seconds`, starting
from the committed corpus (tests/fuzz/corpus/TARGET/) and the target's built seeds, with
checksums switched off. A crash (any exception but the project's errors) stops that target
and is saved as out/fuzz-crashes/crash-TARGET-*; add it to the corpus once fixed, so that
tests/fuzz/test_corpus.py replays it in CI. `--update-corpus` merges what found new
coverage into the committed corpus (the smallest first, at most 40 files of at most 2 KiB
per target).
Prints, per target, the executions done and the crashes found.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "tests" / "fuzz" / "corpus"
OUT = ROOT / "out" / "fuzz-crashes"
MAX_LEN = 2048

_CHILD = """
import sys, atheris
with atheris.instrument_imports(include=["cclogfs"]):
    import cclogfs.store.format, cclogfs.store.index, cclogfs.store.manifest_check, cclogfs.store.records
    import cclogfs.store.segment, cclogfs.store.window, cclogfs.codecs, cclogfs.jsontext.lines
    import cclogfs.upkeep.policy, cclogfs.classifier.model, cclogfs.ingest
from bench._fuzz_targets import run_one
name = sys.argv.pop(1)
atheris.Setup(sys.argv, lambda data: run_one(name, data))
atheris.Fuzz()
"""


def fuzz(target: str, seconds: int, work: Path) -> dict:
    """Run atheris on one target; its executions and crash files."""
    from bench._fuzz_targets import seeds

    corpus = work / target
    corpus.mkdir(parents=True)
    for src in sorted((CORPUS / target).glob("*")) if (CORPUS / target).is_dir() else []:
        shutil.copy(src, corpus / src.name)
    for i, seed in enumerate(seeds(target)):
        (corpus / f"seed-{i}").write_bytes(seed[:MAX_LEN])
    OUT.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-c", _CHILD, target, str(corpus), f"-max_total_time={seconds}", f"-max_len={MAX_LEN}",
           f"-artifact_prefix={OUT}/crash-{target}-", "-print_final_stats=1", "-rss_limit_mb=2048", "-use_value_profile=1"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=seconds + 300)
    runs = re.findall(r"stat::number_of_executed_units:\s*(\d+)", proc.stderr)
    crashes = re.findall(r"Test unit written to (\S+)", proc.stderr)
    tail = [line for line in proc.stderr.splitlines() if "Error" in line or "Exception" in line][-3:]
    return {"executions": int(runs[-1]) if runs else 0, "crashes": crashes, "exit": proc.returncode,
            "corpus": len(list(corpus.iterdir())), "error": tail}  # fmt: skip


def merge(target: str, work: Path, keep: int = 40) -> int:
    """Add to the committed corpus the run's new inputs (libFuzzer keeps only inputs that
    reached new coverage), the smallest first, up to `keep` files per target."""
    dest = CORPUS / target
    dest.mkdir(parents=True, exist_ok=True)
    have = {p.name for p in dest.iterdir()}
    new = sorted((p for p in (work / target).iterdir() if p.name not in have and not p.name.startswith("seed-")),
                 key=lambda p: (p.stat().st_size, p.name))  # fmt: skip
    for src in new[: max(0, keep - len(have))]:
        shutil.copy(src, dest / src.name)
    return len(list(dest.iterdir()))


def main() -> int:
    from bench._fuzz_targets import TARGETS

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=int, default=60, help="per target")
    ap.add_argument("--target", default=",".join(TARGETS), help="comma-separated; default all")
    ap.add_argument("--update-corpus", action="store_true")
    args = ap.parse_args()
    out: dict = {}
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for target in args.target.split(","):
            out[target] = fuzz(target, args.seconds, Path(tmp))
            if args.update_corpus and not out[target]["crashes"]:
                out[target]["committed_corpus"] = merge(target, Path(tmp))
            print(target, json.dumps(out[target]), flush=True)
    total = {"executions": sum(r["executions"] for r in out.values()),
             "crashes": sum(len(r["crashes"]) for r in out.values()), "seconds": round(time.perf_counter() - t)}  # fmt: skip
    print(json.dumps(total))
    from ._util import save_json

    print(f"saved {save_json('fuzz', {'targets': out, 'total': total})}")
    return 1 if total["crashes"] else 0
