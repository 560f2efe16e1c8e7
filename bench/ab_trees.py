"""Time `cclog record` of one input with two trees of cclogfs in one process, alternating.

    python bench/ab_trees.py --base /tmp/before [--pairs 20] INPUT [RECORD OPTIONS...]

A is the checkout this script belongs to; B is the `cclogfs` package under --base (a
`git archive` of another commit, its compiled helpers copied or built in it). B is
copied to a temporary directory as the package `cclogfs_b`, so both import side by side
(the package imports itself only relatively). Each pair runs A and B once, in turn, in
an order that alternates, and times `main(["record", INPUT, "--store", ...])` in CPU
seconds (time.process_time) after a first untimed run of each.

Why in one process: on this shared host the speed of a whole process drifts by 15-40 %
between runs, so a change of 5-10 % needs many pairs of `bench/ab.py` to show. In one
process both trees meet the same drift within a pair, and no start-up or page cache
differs. What this does not see (start-up, imports) `bench/ab.py` does.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, type=Path, help="directory holding tree B's cclogfs package")
    ap.add_argument("--pairs", type=int, default=20)
    ap.add_argument("input", help="what `cclog record` reads")
    ap.add_argument("options", nargs=argparse.REMAINDER, help="more `cclog record` options")
    args = ap.parse_args()
    if not (args.base / "cclogfs" / "__init__.py").exists():
        raise SystemExit(f"{args.base} holds no cclogfs package")
    work = Path(tempfile.mkdtemp(prefix="ab-trees-"))
    try:
        shutil.copytree(args.base / "cclogfs", work / "cclogfs_b", ignore=shutil.ignore_patterns("__pycache__"))
        sys.path[:0] = [str(ROOT), str(work)]
        trees = {"A": importlib.import_module("cclogfs.cli"), "B": importlib.import_module("cclogfs_b.cli")}
        if not trees["A"].__file__.startswith(str(ROOT)):
            raise SystemExit(f"tree A imported from {trees['A'].__file__}, not {ROOT}")

        def once(name: str) -> float:
            store = work / "store"
            shutil.rmtree(store, ignore_errors=True)
            start = time.process_time()
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
                code = trees[name].main(["record", args.input, "--store", str(store), *args.options])
            if code != 0:
                raise SystemExit(f"tree {name}: record exited {code}: {err.getvalue().strip()}")
            return time.process_time() - start

        once("A"), once("B")  # imports and first-call caches, untimed
        times: dict[str, list[float]] = {"A": [], "B": []}
        for i in range(args.pairs):
            for name in ("A", "B") if i % 2 else ("B", "A"):
                times[name].append(once(name))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    ratios = [a / b for a, b in zip(times["A"], times["B"])]
    print(f"A (this checkout) median {statistics.median(times['A']):.3f} s CPU; "
          f"B ({args.base}) median {statistics.median(times['B']):.3f} s")  # fmt: skip
    print(f"A/B CPU, pair by pair: median {statistics.median(ratios):.3f} "
          f"(min {min(ratios):.3f}, max {max(ratios):.3f}, {len(ratios)} pairs)")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
