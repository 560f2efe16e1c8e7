"""I/O errors at every file operation of each store operation, and what they must not do.

For each scenario (an operation on a store: put, sync, roll, seal, close, compaction,
aging, retention, repair, open, create), a dry run counts its file operations; then for
every operation N and every failure mode that applies to it (faultfs.MODES) the scenario
runs again on a fresh copy of its store, with operation N failing. Each run must:

1. end in a project error (CclogError) or succeed: never a raw OSError or another exception;
2. after reopening the store (on the real file system) hold every window acknowledged
   before the failure (by a completed sync, close or commit), byte for byte, except what
   the operation itself meant to change (a drop, an aged or recompressed window);
3. work after reopening: `fsck` finds no error, and a put, a sync and a read succeed.

`run_all(tmp)` returns per scenario the runs and any violation; tests/store/test_io_errors.py
asserts there are none, and `python3 tests/store/io_faults.py` prints the table.
"""

from __future__ import annotations

import json
import shutil
import sys
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cclogfs
from cclogfs.errors import CclogError
from cclogfs.store import Replacement, check_store, repair_store
from cclogfs.store.format import segment_name
from cclogfs.upkeep import Policy, compact, parse_rule
from faultfs import MODES, FaultyFileSystem

OPTS = {"codec": "zstd", "segment_records": 4, "sync_every_ms": None, "sync_every_bytes": None}


def _window(i: int) -> list[tuple[int, str]]:
    return [(i * 100 + k, json.dumps({"i": i, "x": k * 0.123456789, "y": -i / 7})) for k in range(12)]


def _windows(path: Path) -> dict[int, tuple[str, list]]:
    with cclogfs.open_store(path, readonly=True) as store:
        return {w.seq: (w.name, list(w.messages())) for w in store.query()}


def _sealed_store(path: Path, n: int = 10) -> None:
    """Windows 0..n-1, four per segment, closed cleanly: everything acknowledged."""
    with cclogfs.open_store(path, create=True, **OPTS) as store:
        for i in range(n):
            store.put_window("/a" if i % 3 else "/b", _window(i))


def _unclean_store(path: Path) -> None:
    """What a crash can leave: a synced prefix, a tail past it that landed, a torn record
    after that, a half-written manifest replacement."""
    _sealed_store(path, 5)  # segment 0 sealed, segment 4 active
    with cclogfs.open_store(path, **OPTS) as store:
        store.put_window("/a", _window(5))
        store.sync()
        store.put_window("/a", _window(6))
        store.active.flush()  # written, never fsynced
        shutil.copytree(path, str(path) + ".crash")
    shutil.rmtree(path)
    Path(str(path) + ".crash").rename(path)
    (path / "LOCK").unlink()
    active = path / segment_name(4)
    with open(active, "ab") as f:
        f.write(b"CCLR\x01\x02" + b"\x07" * 40)  # a torn record
    (path / "MANIFEST.tmp").write_bytes(b"CCLM half")


@dataclass
class Scenario:
    name: str
    template: Callable[[Path], None] | None  # builds the store the operation starts from
    run: Callable[[Path, FaultyFileSystem], set[int]]  # arms the fs, runs; returns seqs it acknowledged
    changes: str = ""  # what the operation may change: "drop", "age", "recode" or ""


def _open(path: Path, fs: FaultyFileSystem, **kw):
    return cclogfs.open_store(path, fs=fs, **{**OPTS, **kw})


def _closing(store, fs: FaultyFileSystem, body: Callable[[], set[int]]) -> set[int]:
    """Run `body` (armed), then close the store with the faults off, whatever happened."""
    try:
        return body()
    finally:
        fs.armed = False
        try:
            store.close()
        except CclogError:
            pass


def _op_put(path, fs):
    store = _open(path, fs, sync_every_ms=0)
    return _closing(store, fs, lambda: (fs.arm(), {store.put_window("/a", _window(50)).seq})[1])


def _op_sync(path, fs):
    store = _open(path, fs)  # the active segment holds 2 of 4: these stay in it, unsynced
    seqs = {store.put_window("/b", _window(50)).seq}
    return _closing(store, fs, lambda: (fs.arm(), store.sync(), seqs)[2])


def _op_roll(path, fs):
    store = _open(path, fs, sync_every_ms=0)  # 10 windows: the active segment holds 2 of 4
    store.put_window("/a", _window(50))
    return _closing(store, fs, lambda: (fs.arm(), {store.put_window("/a", _window(51)).seq})[1])


def _op_seal(path, fs):
    store = _open(path, fs)
    seq = store.put_window("/a", _window(50)).seq
    return _closing(store, fs, lambda: (fs.arm(), store.seal(), {seq})[2])


def _op_close(path, fs):
    store = _open(path, fs)
    seq = store.put_window("/a", _window(50)).seq
    fs.arm()
    store.close()
    return {seq}


def _op_rewrite(path, fs):
    store = _open(path, fs)

    def recode(w):
        return Replacement(list(w.messages()), dict(w.meta), codec="zstd")

    return _closing(store, fs, lambda: (fs.arm(), store.rewrite(recode), set())[2])


def _op_age(path, fs):
    store = _open(path, fs)
    policy = Policy([parse_rule("1e-3")])
    return _closing(store, fs, lambda: (fs.arm(), compact(store, policy=policy), set())[2])


def _op_retain(path, fs):
    store = _open(path, fs)
    budget = store.data_bytes() // 2
    return _closing(store, fs, lambda: (fs.arm(), compact(store, budget=budget), set())[2])


def _op_repair(path, fs):
    fs.arm()
    repair_store(str(path), fs=fs)
    return set()


def _op_open(path, fs):
    fs.arm()
    store = _open(path, fs)
    return _closing(store, fs, lambda: set())


def _op_create(path, fs):
    shutil.rmtree(path)
    fs.arm()
    store = _open(path, fs, create=True)
    return _closing(store, fs, lambda: (store.put_window("/a", _window(0)), store.sync(), {0})[2])


def _repair_template(path: Path) -> None:
    _sealed_store(path)
    (path / "00000000000000000004.idx").unlink()  # repair rebuilds it


SCENARIOS = [
    Scenario("put", _sealed_store, _op_put),
    Scenario("sync", _sealed_store, _op_sync),
    Scenario("roll", _sealed_store, _op_roll),
    Scenario("seal", _sealed_store, _op_seal),
    Scenario("close", _sealed_store, _op_close),
    Scenario("compaction", _sealed_store, _op_rewrite, "recode"),
    Scenario("aging", _sealed_store, _op_age, "age"),
    Scenario("retention", _sealed_store, _op_retain, "drop"),
    Scenario("repair", _repair_template, _op_repair),
    Scenario("open", _unclean_store, _op_open),
    Scenario("create", _sealed_store, _op_create),
]


@dataclass
class Outcome:
    runs: int = 0
    errors: int = 0  # runs that ended in a project error
    modes: dict[str, int] = field(default_factory=dict)
    violations: list[str] = field(default_factory=list)


def _check_after(path: Path, before: dict, acked: set[int], new: dict, changes: str) -> list[str]:
    """What is wrong with the store at `path` after a run (empty: nothing)."""
    try:
        with cclogfs.open_store(path, **OPTS) as store:
            first = store.first_seq
            got = {w.seq: (w.name, list(w.messages()), w.aged) for w in store.query()}
            seq = store.put_window("/z", _window(99)).seq
            store.sync()
            assert [w.seq for w in store.query("/z")][-1] == seq
    except Exception as err:  # noqa: BLE001 - any failure here is the finding
        return [f"reopening and writing failed: {type(err).__name__}: {err}"]
    problems = []
    want = dict(before)
    want.update({s: new[s] for s in acked})
    for s, (name, msgs) in sorted(want.items()):
        if changes == "drop" and s < first:
            continue
        if s not in got:
            problems.append(f"acknowledged seq {s} lost")
        elif got[s][:2] != (name, msgs):
            aged_ok = changes == "age" and got[s][2] is not None and [m[0] for m in got[s][1]] == [m[0] for m in msgs]
            if not aged_ok:
                problems.append(f"acknowledged seq {s} changed")
    report = check_store(str(path))
    problems += [f"fsck after reopening: {f.where}: {f.what}" for f in report.errors]
    return problems


def run_scenario(sc: Scenario, tmp: Path, limit: int | None = None) -> Outcome:
    out = Outcome()
    template = tmp / f"{sc.name}.template"
    template.mkdir(parents=True)
    shutil.rmtree(template)
    sc.template(template)
    before = _windows(template) if sc.name != "create" else {}
    # The dry run: how many operations, and which.
    work = tmp / f"{sc.name}.run"
    shutil.copytree(template, work)
    fs = FaultyFileSystem()
    sc.run(work, fs)
    ops = list(fs.armed_ops)
    new = {s: v for s, v in _windows(work).items() if s not in before}
    if sc.name == "create":
        before = {}
    for n, (kind, _name) in enumerate(ops[:limit], start=1):
        for mode in MODES[kind]:
            shutil.rmtree(work)
            shutil.copytree(template, work)
            fs = FaultyFileSystem(at=n, mode=mode)
            out.runs += 1
            out.modes[mode] = out.modes.get(mode, 0) + 1
            acked: set[int] = set()
            where = f"{sc.name}: op {n} ({kind} {_name}) {mode}"
            try:
                acked = sc.run(work, fs)
            except CclogError:
                out.errors += 1
            except BaseException as err:  # noqa: BLE001 - the finding
                tb = traceback.extract_tb(err.__traceback__)[-1]
                out.violations.append(f"{where}: raw {type(err).__name__}: {err} "
                                      f"({Path(tb.filename).name}:{tb.lineno})")  # fmt: skip
                out.errors += 1
            fs.armed = False
            if sc.name == "create" and not (work / "MANIFEST").exists():
                if work.exists() and any(work.iterdir()):
                    out.violations.append(f"{where}: a half-made store was left: {sorted(p.name for p in work.iterdir())}")
                work.mkdir(exist_ok=True)
                continue
            out.violations += [f"{where}: {p}" for p in _check_after(work, before, acked, new, sc.changes)]
    return out


def run_all(tmp: Path, names=None) -> dict[str, Outcome]:
    return {sc.name: run_scenario(sc, tmp) for sc in SCENARIOS if names is None or sc.name in names}


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory(dir="/dev/shm" if Path("/dev/shm").is_dir() else None) as d:
        results = run_all(Path(d), sys.argv[1:] or None)
    total = sum(o.runs for o in results.values())
    for name, o in results.items():
        print(f"{name:11} {o.runs:5} runs {o.errors:5} project errors  {len(o.violations):4} violations  {o.modes}")
        for v in o.violations[:8]:
            print("   ", v)
    print(f"total {total} runs, {sum(len(o.violations) for o in results.values())} violations")
