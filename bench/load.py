"""Readers under load (issue 16, "Load"): readers in a loop while a writer records, seals,
compacts (ages) and drops segments. A false error is any error a reader reports on a store
that holds no damage: the count must be 0.

    python -m bench load [--seconds 600] [--cat-every 20] [--fsck-every 10]

The writer is a separate process (as `cclog record` is); the readers take turns in this
one: library queries that open a store and read every window, one long-lived reader that
calls `refresh()`, `fsck --deep` (check_store), and `cclog cat` as a subprocess.
tests/store/test_load.py runs the same code for a few seconds.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import cclogfs
from cclogfs.errors import CclogError
from cclogfs.store import Replacement, check_store
from cclogfs.store.format import RecordFlag

STREAMS = ("/odom", "/tf", "/scan")


def _message(i: int, k: int) -> str:
    return json.dumps({"i": i, "k": k, "x": round(0.1 * k + i, 3), "pad": "p" * (i % 97 + 600 * (i % 10 == 9))})


def _aged(window):
    """Aging as compaction does it: every other message, values rounded, flagged AGED."""
    kept = list(window.messages())[::2]
    return Replacement([(t, json.dumps({"r": round(len(text) / 10)})) for t, text in kept],
                       dict(window.meta, aged={"abs": 5}), flags=RecordFlag.AGED)  # fmt: skip


def write(path: str, stop, puts) -> None:
    """Record until `stop` is set: windows of a few messages on three streams; every so
    often age the oldest sealed segment and, beyond eight sealed ones, drop the oldest."""
    with cclogfs.open_store(path, create=True, sync_every_ms=20, segment_records=40,
                            segment_bytes=1 << 20) as store:  # fmt: skip
        i = 0
        while not stop.is_set():
            # Every tenth window is a large /scan (~200 KB, stored as is): its write spans many
            # pages, so readers also open while a record is only partly in the file.
            n, codec = (300, "none") if i % 10 == 9 else (1 + i % 30, None)
            store.put_window(STREAMS[i % 3], [(i * 1000 + k, _message(i, k)) for k in range(n)], meta={"i": i},
                             codec=codec)  # fmt: skip
            i += 1
            puts.value = i
            if i % 150 == 0:
                sealed = store.sealed_segments()
                fresh = [s.first_seq for s in sealed if not s.aged]
                if fresh:
                    store.rewrite(lambda w: _aged(w) if w.start_ns % 2 == 0 else None, segments=fresh[:1])
                if len(sealed) > 8:
                    store.drop_oldest()


@dataclass
class Tally:
    reads: int = 0  # windows read back (every message decoded)
    opens: int = 0  # stores opened or refreshed
    fscks: int = 0  # fsck runs (every --fsck-every th one --deep)
    cats: int = 0
    attempts: int = 0  # manifest reads of the library opens and refreshes (1 each without a retry)
    most_attempts: int = 0  # of one open
    errors: list[str] = field(default_factory=list)


def _read_all(store, tally: Tally, since: int | None = None) -> None:
    for window in store.query(start_ns=since):
        for _ in window.messages():
            pass
        tally.reads += 1


def _count_open(store, tally: Tally) -> None:
    tally.opens += 1
    tally.attempts += store.open_attempts
    tally.most_attempts = max(tally.most_attempts, store.open_attempts)


def _one_round(path: str, reader, tally: Tally, n: int, puts, cat_every: int, fsck_every: int) -> None:
    """One round of every kind of reader. Fresh opens read only the last windows (those of
    the active segment, where the writer appends): many opens land during an append."""
    try:
        for _ in range(5):
            with cclogfs.open_store(path, readonly=True) as store:
                _count_open(store, tally)
                _read_all(store, tally, since=(puts.value - 100) * 1000)
        reader.refresh()
        _count_open(reader, tally)
        _read_all(reader, tally)
    except CclogError as err:
        tally.errors.append(f"library: {err}")
    report = check_store(path, deep=n % fsck_every == 0)
    tally.fscks += 1
    tally.errors += [f"fsck: {f}" for f in report.errors]
    if n % cat_every == 0:
        cclog = str(Path(sys.executable).with_name("cclog"))
        done = subprocess.run([cclog, "cat", path], capture_output=True, text=True)
        tally.cats += 1
        if done.returncode != 0 or not done.stdout:
            tally.errors.append(f"cat: exit {done.returncode}: {done.stderr.strip()}")


def run(seconds: float, *, cat_every: int = 20, fsck_every: int = 10, workdir: str | None = None) -> Tally:
    """Readers in a loop for `seconds` while a writer process works on a new store."""
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        path = str(Path(tmp) / "s")
        ctx = multiprocessing.get_context("spawn")
        stop, puts = ctx.Event(), ctx.Value("q", 0)
        writer = ctx.Process(target=write, args=(path, stop, puts))
        writer.start()
        tally = Tally()
        try:
            while puts.value < 50:  # the store exists and holds something
                if not writer.is_alive():
                    raise RuntimeError("the writer died before writing")
                time.sleep(0.05)
            reader = cclogfs.open_store(path, readonly=True)
            end, n = time.monotonic() + seconds, 0
            while time.monotonic() < end:
                n += 1
                _one_round(path, reader, tally, n, puts, cat_every, fsck_every)
            reader.close()
        finally:
            stop.set()
            writer.join(60)
        if writer.exitcode != 0:
            tally.errors.append(f"writer exited {writer.exitcode}")
        with cclogfs.open_store(path, readonly=True) as store:  # what the load left is sound
            _read_all(store, tally)
        tally.errors += [f"fsck after: {f}" for f in check_store(path, deep=True).errors]
        tally.puts = puts.value
    return tally


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=600)
    parser.add_argument("--cat-every", type=int, default=20, help="a `cclog cat` every N rounds")
    parser.add_argument("--fsck-every", type=int, default=10, help="fsck each round, --deep every N rounds")
    args = parser.parse_args()
    start = time.monotonic()
    tally = run(args.seconds, cat_every=args.cat_every, fsck_every=args.fsck_every)
    print(f"load: {time.monotonic() - start:.0f} s, writer puts {tally.puts}, windows read {tally.reads}, "
          f"opens/refreshes {tally.opens} ({tally.attempts / max(1, tally.opens):.3f} manifest reads each, "
          f"at most {tally.most_attempts}), fsck {tally.fscks}, cclog cat {tally.cats}, "
          f"false errors {len(tally.errors)}")  # fmt: skip
    for err in tally.errors[:20]:
        print(f"  {err}")
    return 1 if tally.errors else 0


if __name__ == "__main__":
    sys.exit(main())
