"""kill -9 at random instants, with a reader reading all along, and the checks after each
(issue 16): shared by tests/cli/test_kill9.py and tests/ingest/test_ros1live_kill9.py."""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import random
import shutil
import signal
import threading
import time
from pathlib import Path

import cclogfs
from cclogfs.errors import CclogError
from cclogfs.store import check_store, repair_store


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
    if os.WIFEXITED(status):  # it finished between the look and the kill
        assert os.WEXITSTATUS(status) == 0, status
        return False
    assert os.WTERMSIG(status) == signal.SIGKILL, status
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


def kills(base: Path, n: int, start, seed: int) -> tuple[int, int, list[str]]:
    """n runs started by `start(store)` (a pid), each killed at a random instant of the time a
    whole run takes (the first run's, shortened whenever a run ends before its kill: on a
    loaded host the first run can take many times what the later ones do); returns (kills
    that landed, reads, reader errors)."""
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
            delay = rng.uniform(0, whole * 0.9)
            if kill_at(pid, delay):
                landed += 1
            else:  # the run ended within `delay`: the first run was slow (a loaded host); aim shorter
                whole = delay
        reader.stop.set()
        reader.join()
        reads += reader.reads
        errors += reader.errors
        check_after_kill(store, reader.seen)
        shutil.rmtree(store, ignore_errors=True)
    return landed, reads, errors
