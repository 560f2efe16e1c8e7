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

import hashlib
import itertools
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import cclogfs
from cclogfs.errors import CclogError
from cclogfs.store import check_store, repair_store
from test_hard_kill import odom_line

RECORD_KILLS = 150
COMPACT_KILLS = 50
SPAWNED_KILLS = 3  # whole `python -m cclogfs record` processes
LINES = 800
UPKEEP = ["--budget", "200KiB", "--age-older-than", "2s", "--age-error", "1e-3"]


def record_argv(src: Path, store: Path) -> list[str]:
    return ["record", str(src), "--store", str(store), "--chunk", "10", "--sync-ms", "5", "--codec", "none",
            *UPKEEP]  # fmt: skip


def compact_argv(store: Path) -> list[str]:
    return ["compact", str(store), "--older-than", "0s", "--error", "1e-2", "--budget", "100KiB"]


def fork_cli(argv: list[str]) -> int:
    """A child process running `cclog ARGV` (stdin, stdout and stderr to /dev/null)."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        code = 70
        try:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            null = os.open(os.devnull, os.O_RDWR)
            for fd in (0, 1, 2):
                os.dup2(null, fd)
            from cclogfs.cli import main

            code = main(argv) or 0
        except SystemExit as err:
            code = err.code if isinstance(err.code, int) else 1
        except BaseException:  # noqa: BLE001 - only the exit status leaves the child
            code = 71
        finally:
            os._exit(code)
    return pid


def kill_at(pid: int, delay: float) -> bool:
    """SIGKILL `pid` after `delay` seconds; whether it was still running (a real kill)."""
    time.sleep(delay)
    done, _status = os.waitpid(pid, os.WNOHANG)
    if done:
        return False
    os.kill(pid, signal.SIGKILL)
    _pid, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
    return True


def run_to_end(pid: int) -> float:
    t0 = time.monotonic()
    _pid, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, status
    return time.monotonic() - t0


def digest(messages) -> str:
    return hashlib.blake2b(json.dumps(messages).encode(), digest_size=12).hexdigest()


class Reader(threading.Thread):
    """Reads the store over and over: seq -> (stream, stamps, digest, aged) of every window seen."""

    def __init__(self, path: Path):
        super().__init__(daemon=True)
        self.path, self.stop, self.seen, self.errors, self.reads = path, threading.Event(), {}, [], 0

    def run(self) -> None:
        while not self.stop.is_set():
            if not (self.path / "MANIFEST").exists():
                time.sleep(0.002)
                continue
            try:
                with cclogfs.open_store(self.path, readonly=True) as store:
                    for w in store.query():
                        messages = list(w.messages())
                        self.seen[w.seq] = (w.name, [t for t, _ in messages], digest(messages), bool(w.aged))
                        self.reads += 1
            except CclogError as err:  # the writer changed the store under it: counted, read again
                self.errors.append(f"{type(err).__name__}: {err}")


def check_after_kill(path: Path, seen: dict) -> None:
    if not (path / "MANIFEST").exists():  # killed before the store was made: all or nothing
        assert not path.exists() and not seen
        return
    report = check_store(str(path), deep=True)
    assert report.errors == [], [str(f) for f in report.errors]
    repair_store(str(path))
    again = check_store(str(path), deep=True)
    assert again.findings == [], [str(f) for f in again.findings]
    with cclogfs.open_store(path, sync_every_ms=None) as store:
        assert store.damage() == [] and not store.recovery.problems
        windows = sorted(store.query(), key=lambda w: w.seq)
        first = store.first_seq
        assert [w.seq for w in windows] == list(range(first, first + len(windows))), "a hole"
        now = {w.seq: w for w in windows}
        for seq, (name, stamps, dig, aged) in seen.items():
            if seq < first:
                continue  # retention dropped its segment
            assert seq in now, f"seq {seq}, seen by the reader, is gone (log {first}..{first + len(windows) - 1})"
            w = now[seq]
            messages = list(w.messages())
            assert w.name == name
            if w.aged or aged:
                assert {t for t, _ in messages} <= set(stamps) or set(stamps) <= {t for t, _ in messages}
            else:
                assert digest(messages) == dig, f"seq {seq} changed"


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    src = tmp_path_factory.mktemp("kill9") / "odom.jsonl"
    src.write_text("".join(odom_line(i) for i in range(LINES)))
    return src


def kills(base: Path, n: int, start, seed: int) -> tuple[int, int, list[str]]:
    """n runs started by `start(store)` (a pid), each killed at a random instant of the time a
    whole run takes; returns (kills that landed, reads, reader errors)."""
    rng = random.Random(seed)
    landed, reads, errors = 0, 0, []
    whole = None
    for i in itertools.count():
        if landed == n or i > 3 * n:
            break
        store = base / f"s{i}"
        reader = Reader(store)
        reader.start()
        pid = start(store)
        if whole is None:  # the first run goes to its end: how long a run takes
            whole = run_to_end(pid)
        else:
            landed += kill_at(pid, rng.uniform(0, whole * 0.9))
        reader.stop.set()
        reader.join()
        reads += reader.reads
        errors += reader.errors
        check_after_kill(store, reader.seen)
        shutil.rmtree(store, ignore_errors=True)
    return landed, reads, errors


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
    assert landed == COMPACT_KILLS, landed


def test_kill_9_of_whole_cli_processes(source, tmp_path):
    def start(store):
        return subprocess.Popen([sys.executable, "-m", "cclogfs", *record_argv(source, store)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).pid  # fmt: skip

    landed, _reads, _errors = kills(tmp_path, SPAWNED_KILLS, start, 3)
    assert landed == SPAWNED_KILLS, landed
