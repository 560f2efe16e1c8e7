"""Time two commands against each other, whole process, in alternating pairs.

    python bench/ab.py -n 7 --vs "B COMMAND" -- A COMMAND ARGS...

A and B run in turn (A B A B ...), each as a child process without a shell (B's string
is split as a shell splits words; use `sh -c '...'` for a pipe or a cleanup step). For
each run: wall seconds, CPU seconds (user + sys, from the child's rusage) and peak RSS.
The report gives medians, min and max of each, and the A/B ratios taken pair by pair:
pairing keeps the ratio meaningful when a shared machine's speed drifts during the call,
which is why the CPU ratio, not an absolute figure, is what to quote from a loaded host.

To compare two trees of cclogfs, run each with PYTHONPATH set to it from a directory that
holds no `cclogfs` package (`cd /tmp`): `python -c` puts the working directory first on
sys.path, so from a checkout both commands would import the checkout's package and the
ratio would read 1.0 whatever the trees hold (issue 14, thirteenth pass: it did).

Public tools only (the standard library), so that anyone can rerun a figure quoted in
docs/MEASURED.md.
"""

from __future__ import annotations

import argparse
import os
import shlex
import statistics
import subprocess
import sys
import time


def run_once(argv: list[str], timeout: float | None) -> tuple[float, float, float, int]:
    """(wall s, cpu s, peak MiB, exit status) of one run of argv."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL)
    deadline = None if timeout is None else start + timeout
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if deadline is not None and time.perf_counter() > deadline:
            proc.kill()
            pid, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.002)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)  # so Popen does not wait again
    # ru_maxrss is in KiB on Linux.
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, proc.returncode


def _row(name: str, values: list[float], fmt: str) -> str:
    return (f"{name:<12} median {format(statistics.median(values), fmt):>9}"
            f"  min {format(min(values), fmt):>9}  max {format(max(values), fmt):>9}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-n", type=int, default=5, help="runs of each command (default 5)")
    p.add_argument("--vs", metavar="COMMAND_B", help="the baseline, one string split as a shell does")
    p.add_argument("--timeout", type=float, help="seconds a run may take before it is killed")
    p.add_argument("command", nargs=argparse.REMAINDER, help="-- A's command and arguments")
    args = p.parse_args(argv)
    a = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not a:
        p.error("give A's command after --")
    if args.n < 1:
        p.error("-n must be at least 1")
    b = shlex.split(args.vs) if args.vs else None
    runs: dict[str, list[tuple[float, float, float, int]]] = {"A": [], "B": []}
    for _ in range(args.n):
        for name, cmd in (("A", a), ("B", b)):
            if cmd is not None:
                runs[name].append(run_once(cmd, args.timeout))
    failed = 0
    for name in ("A", "B"):
        if not runs[name]:
            continue
        wall, cpu, rss, codes = zip(*runs[name])
        print(f"== {name}: {' '.join(a if name == 'A' else b)}")
        print(_row("wall s", list(wall), ".3f"))
        print(_row("cpu s", list(cpu), ".3f"))
        print(_row("peak MiB", list(rss), ".1f"))
        bad = [c for c in codes if c != 0]
        if bad:
            failed = 1
            print(f"exit         {len(bad)} of {len(codes)} runs failed (status {bad[0]})")
    if b is not None:
        for i, what in ((1, "cpu"), (0, "wall")):
            ratios = [ra[i] / rb[i] for ra, rb in zip(runs["A"], runs["B"]) if rb[i] > 0]
            if ratios:
                print(f"A/B {what:<8} median {statistics.median(ratios):9.3f}"
                      f"  min {min(ratios):9.3f}  max {max(ratios):9.3f}  ({len(ratios)} pairs)")
    return failed


if __name__ == "__main__":
    sys.exit(main())
