"""Bit-flip trials (issue 11, "what must hold"): damage one bit, or zero one 512-byte
sector, of every file kind of a small store closed cleanly or cut by a crash, then check:

- fsck flags the change (any finding);
- no query returns a changed message (a window either reads exactly as put, or fails);
- after a writer's reopen, a further write, another reopen and `fsck --repair`, every
  record that was synced and whose bytes the flip did not touch is readable (as itself, or
  salvaged): the count of intact records lost must be 0.

    python -m bench bitflip [--trials 20000] [--seed 1]

A damaged MANIFEST makes the store refuse to open (one line naming it) until `fsck
--repair` rebuilds it from the segment files; such trials count as 'refused' (then the
repaired store is held to the same measure; the further write is skipped). tests/store/test_bitflip.py runs a few hundred trials of the same code.
"""

from __future__ import annotations

import argparse
import json
import random
import shutil
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import cclogfs
from cclogfs.errors import CclogError
from cclogfs.store import check_store, repair_store

OPTS = dict(codec="zstd", segment_records=4, sync_every_ms=None, sync_every_bytes=None)
KINDS = ("MANIFEST", "sealed segment", "active segment", "index")


@dataclass
class Base:
    """A store's files, what each seq holds, which seqs were synced, where records lie."""

    files: dict[str, bytes]
    windows: dict[int, tuple[str, list]]
    synced: set[int]
    ranges: dict[str, list[tuple[int, int, int]]]  # file -> (start, end, seq)
    crashed: bool


def _put(store, i: int) -> None:
    store.put_window("/odom" if i % 3 else "/tf", [(i * 100 + k, json.dumps({"i": i, "k": k})) for k in range(5)],
                     meta={"i": i})  # fmt: skip


def build(root: Path, crashed: bool) -> Base:
    path = root / ("crashed" if crashed else "clean")
    with cclogfs.open_store(path, create=True, **OPTS) as store:
        for i in range(10):
            _put(store, i)
            if i % 3 == 2:
                store.sync()
    synced = set(range(10))
    if crashed:  # a second process puts 3 more, hands them to the OS, and is killed
        store = cclogfs.open_store(path, **OPTS)
        for i in range(10, 13):
            _put(store, i)
        store.active.flush()
        store._closed = True
        store.fs.unlock(store._lock_fd)
    with cclogfs.open_store(path, readonly=True) as store:
        windows = {w.seq: (w.name, list(w.messages())) for w in store.query()}
        ranges: dict[str, list] = {}
        for w in store.query():
            ranges.setdefault(Path(w.segment_path).name, []).append((w.offset, w.offset + w.stored_bytes, w.seq))
    files = {p.name: p.read_bytes() for p in path.iterdir() if p.is_file() and p.name != "LOCK"}
    return Base(files, windows, synced, ranges, crashed)


def _file_of(base: Base, kind: str, rng: random.Random) -> str:
    segs = sorted(n for n in base.files if n.endswith(".seg"))
    if kind == "MANIFEST":
        return "MANIFEST"
    if kind == "index":
        return rng.choice(sorted(n for n in base.files if n.endswith(".idx")))
    return segs[-1] if kind == "active segment" else rng.choice(segs[:-1])


@dataclass
class Result:
    kind: str
    mode: str
    flagged: bool = False
    changed: int = 0  # messages a query returned that differ from what was put
    lost: list[int] = field(default_factory=list)  # intact synced records not readable at the end
    refused: bool = False  # the store would not open (a damaged MANIFEST)


def trial(base: Base, rng: random.Random, work: Path, kind: str, mode: str) -> Result | None:
    """One damaged copy of `base`; None when the change was no change (zeros over zeros)."""
    name = _file_of(base, kind, rng)
    data = bytearray(base.files[name])
    if mode == "bit":
        pos = rng.randrange(len(data))
        data[pos] ^= 1 << rng.randrange(8)
        lo, hi = pos, pos + 1
    else:
        lo = rng.randrange(max(1, len(data) // 512 + (len(data) % 512 > 0))) * 512
        hi = min(len(data), lo + 512)
        data[lo:hi] = bytes(hi - lo)
    if bytes(data) == base.files[name]:
        return None
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    for n, content in base.files.items():
        (work / n).write_bytes(bytes(data) if n == name else content)
    touched = {seq for start, end, seq in base.ranges.get(name, ()) if start < hi and lo < end}
    result = Result(kind, mode)
    result.flagged = bool(check_store(str(work), deep=True).findings)
    result.changed = _changed(base, work)
    try:
        with cclogfs.open_store(work, **OPTS) as store:
            store.put_window("/after", [(10**12, "{}")])
        with cclogfs.open_store(work, **OPTS):
            pass
    except CclogError:
        result.refused = True  # a damaged MANIFEST: the store refuses until repaired
    try:
        repair_store(str(work))
        readable = _readable(base, work)
    except CclogError:  # a repair that cannot finish loses what it cannot show
        readable = set()
    result.lost = sorted(base.synced - touched - readable)
    result.changed += _changed(base, work)
    return result


def _changed(base: Base, path: Path) -> int:
    """Messages a query returns that differ from what was put (0 when it cannot open)."""
    bad = 0
    try:
        with cclogfs.open_store(path, readonly=True) as store:
            for w in store.query(skip_damaged=True):
                seq = (w.meta.get("salvaged") or {}).get("seq", w.seq) if w.name != "/after" else None
                try:
                    got = (w.name, list(w.messages()))
                except CclogError:
                    continue
                if seq is not None and got != base.windows.get(seq):
                    bad += 1
    except CclogError:
        pass
    return bad


def _readable(base: Base, path: Path) -> set[int]:
    found = set()
    with cclogfs.open_store(path, readonly=True) as store:
        for w in store.query(skip_damaged=True):
            if w.name == "/after":
                continue
            seq = (w.meta.get("salvaged") or {}).get("seq", w.seq)
            try:
                if (w.name, list(w.messages())) == base.windows.get(seq):
                    found.add(seq)
            except CclogError:
                pass
    return found


def run(trials: int, seed: int, root: Path) -> dict:
    rng = random.Random(seed)
    bases = [build(root, crashed=False), build(root, crashed=True)]
    totals: Counter = Counter()
    failures: list[dict] = []
    for i in range(trials):
        base = bases[i % 2]
        kind = KINDS[(i // 2) % len(KINDS)]
        mode = "sector" if i % 10 == 9 else "bit"
        r = trial(base, rng, root / "work", kind, mode)
        if r is None:
            totals["no change"] += 1
            continue
        totals["trials"] += 1
        totals[f"{mode} flips"] += 1
        totals["refused until repair (damaged MANIFEST)"] += r.refused
        totals["not flagged by fsck"] += not r.flagged
        totals["changed messages returned"] += r.changed
        totals["intact synced records lost"] += len(r.lost)
        if not r.flagged or r.changed or r.lost or (r.refused and kind != "MANIFEST"):
            failures.append({"i": i, "crashed": base.crashed, "kind": kind, "mode": mode, "flagged": r.flagged,
                             "changed": r.changed, "lost": r.lost, "refused": r.refused})  # fmt: skip
    return {"totals": dict(totals), "failures": failures[:50], "failure_count": len(failures)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=20000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    t = time.perf_counter()
    # tmpfs when there is one: the trials fsync often, and no crash is simulated here.
    shm = "/dev/shm" if Path("/dev/shm").is_dir() else None
    with tempfile.TemporaryDirectory(dir=shm) as tmp:
        out = run(args.trials, args.seed, Path(tmp))
    out["seconds"] = round(time.perf_counter() - t, 1)
    from ._util import save_json

    print(json.dumps(out, indent=1))
    print(f"saved {save_json('bitflip', out)}")
    return 1 if out["failure_count"] else 0
