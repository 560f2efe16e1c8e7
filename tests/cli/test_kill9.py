"""Issue 16, "kill -9": the real CLI killed at random instants while a reader reads.

`cclog record` from a JSONL file with a budget and aging, and `cclog compact`, are killed
with SIGKILL at a random instant of their run, many times over. Most runs are forked from
this process with the CLI already imported (its `main`, as `cclog` runs it: only the
interpreter's start-up is saved, so that 200 kills fit in CI); a few are whole
`python -m cclogfs` processes. A reader thread opens, queries and reads the store the
whole time. After each kill:

- fsck finds no error (a torn tail the writer will cut, or a compaction's leftovers, are
  warnings), `fsck --repair` leaves nothing for a second fsck to find;
- the store opens and holds a gapless run of seqs from its first, no damage;
- every window the reader saw (so handed to the OS, which a kill does not lose) is still
  there with the same stream and messages, unless retention dropped its segment (its seq
  is before the store's first) or aging rewrote it (then its stamps are a subset).

Kills that land after the run finished are not counted.
"""

from __future__ import annotations

import shutil
from collections import Counter
import subprocess
import sys
from pathlib import Path

import pytest

from _kill9 import fork_cli, kills, run_to_end
from test_hard_kill import odom_line

RECORD_KILLS = 150
COMPACT_KILLS = 50
SPAWNED_KILLS = 10  # whole `python -m cclogfs record` processes
LINES = 800
UPKEEP = ["--budget", "200KiB", "--age-older-than", "2s", "--age-error", "1e-3"]


def record_argv(src: Path, store: Path) -> list[str]:
    return ["record", str(src), "--store", str(store), "--chunk", "10", "--sync-ms", "5", "--codec", "none",
            *UPKEEP]  # fmt: skip


def compact_argv(store: Path) -> list[str]:
    return ["compact", str(store), "--older-than", "0s", "--error", "1e-2", "--budget", "100KiB"]


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    src = tmp_path_factory.mktemp("kill9") / "odom.jsonl"
    src.write_text("".join(odom_line(i) for i in range(LINES)))
    return src


def test_kill_9_of_record_with_budget_and_aging(source, tmp_path):
    landed, reads, errors = kills(tmp_path, RECORD_KILLS, lambda s: fork_cli(record_argv(source, s)), 1)
    print(f"record: {landed} kills landed, {reads} windows read meanwhile, {len(errors)} reader errors")
    assert landed == RECORD_KILLS, landed
    assert reads > 0


def test_kill_9_of_compact(source, tmp_path):
    base = tmp_path / "base"
    run_to_end(fork_cli(["record", str(source), "--store", str(base), "--chunk", "10", "--codec", "none"]))

    def start(store):
        shutil.copytree(base, store)
        return fork_cli(compact_argv(store))

    landed, reads, errors = kills(tmp_path, COMPACT_KILLS, start, 2)
    print(f"compact: {landed} kills landed, {reads} windows read meanwhile, {len(errors)} reader errors")
    for what, n in Counter(e.split(":")[0] + ": ..." + e[-90:] for e in errors).most_common(4):
        print(f"  {n} x {what}")
    assert landed == COMPACT_KILLS, landed


def test_kill_9_of_whole_cli_processes(source, tmp_path):
    def start(store):
        return subprocess.Popen([sys.executable, "-m", "cclogfs", *record_argv(source, store)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).pid  # fmt: skip

    landed, _reads, _errors = kills(tmp_path, SPAWNED_KILLS, start, 3)
    assert landed == SPAWNED_KILLS, landed
