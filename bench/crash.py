"""Crash states (issue 16, "The evidence"): run workloads on a recording in-memory file
system, and at every operation boundary open every disk image a crash could leave.

    python3 dev.py bench crash [--states 1000000] [--seed 1] [--long 20] [--max-s S]

Workloads: every sequence of up to 3 operations (as CrashMonkey's ACE) of put, big put
(handed to the OS unsynced), sync, close and reopen, kill -9 and reopen on the same page
cache, seal, age (rewrite), drop the oldest segment, and a failed fsync (then reopen),
after a synced start; then random longer ones (with split puts too: a window over the
record limit, stored as parts flagged PART), and every fourth run the group-commit
thread and the upkeep (aging) thread working on their own. At each boundary: one image per
failure mode for every file (lost, all, prefix, torn, zero, garbage, reorder, hole), plus
MIXED images where each file fails in its own mode and directory operations land
reordered. For an eighth of the new images, the recovery that opens it and `fsck --repair`
are crashed again at each of their own boundaries.

The check of each image: the store opens; it holds a gapless run of seqs that starts where
retention left the log, each window the one put with that seq (messages exact, or aged
within its time range after an age step), ending at or after every put an fsync had made
durable (a sync, a group commit, a close, or recovery's own rewrite), and never inside a
split put (a prefix of its parts); it names no damage;
it takes a put, and reopens clean. Identical images are opened once: the figure is the
number of distinct crash states checked (the number of images made is printed too).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import os
import random
import sys
import time
from dataclasses import dataclass, field

import cclogfs
from cclogfs.errors import StoreFailedError
from cclogfs.store import Replacement, repair_store
from cclogfs.store.format import SEGMENT_HEADER_SIZE, RecordError, RecordFlag
from cclogfs.store import encode, segment
from cclogfs.store.encode import split_bounds
from cclogfs.store.records import BytesAt, UnfinishedPut, records

from ._diskmodel import MODES, DiskModel
from ._memfs import MemFileSystem, RecordingMemFileSystem

DIR = "/cclogfs-crash-store"  # its parent is "/": creation lists the real parent for stale creations
OPTS = dict(sync_every_ms=None, segment_bytes=4096, segment_records=4, codec="zstd")
STEPS = ("put", "big", "sync", "reopen", "kill", "seal", "age", "drop", "failsync")
# A split put (do_split): the random long workloads use it too; tests/store/test_crash_split.py
# checks every workload of a step, a split and a step.
LONG_STEPS = (*STEPS, "split")
SPLIT_RAW = 600  # the record limit a split put is stored under: its 24 messages make 4-5 parts
MIXED = 3  # images per boundary where each file fails in its own mode
WRITE_EVERY = 4  # every 4th distinct image is also written to and reopened (it costs twice the open)


def _pad(t: int, n: int) -> str:
    return hashlib.blake2b(str(t).encode()).hexdigest()[:n]


def digest(name: str, messages) -> bytes:
    return hashlib.blake2b(json.dumps([name, list(messages)]).encode(), digest_size=12).digest()


@dataclass
class Put:
    """What one seq must hold: a put, or one part of a split put (`last`: its final part)."""

    name: str
    messages: list
    digest: bytes
    last: bool = True


@dataclass
class Trace:
    """One workload's operations and, per operation, what a crash image must hold."""

    ops: list = field(default_factory=list)
    refs: list = field(default_factory=list)  # per op: the puts a store holds a prefix of
    first_seqs: list = field(default_factory=list)  # per op: where retention may have left the log
    begin: int = 0  # images from this op on


class Workload:
    """Runs steps on a store over a RecordingMemFileSystem and notes, per op, the reference."""

    def __init__(self, sync_every_bytes: int | None, fs: RecordingMemFileSystem | None = None):
        self.fs = fs or RecordingMemFileSystem()
        self.opts = dict(OPTS, sync_every_bytes=sync_every_bytes, fs=self.fs)
        self.puts: list[Put] = []
        self.trace = Trace()
        self.t = 0
        self.store = cclogfs.open_store(DIR, create=True, **self.opts)
        self.first_before = 0

    def note(self) -> None:
        """Ops since the last note ran under the current reference."""
        n = len(self.fs.ops) - len(self.trace.refs)
        first = self.store.first_seq if not self.store._closed else self.first_before
        self.trace.refs += [tuple(self.puts)] * n
        self.trace.first_seqs += [frozenset((self.first_before, first))] * n

    def step(self, name: str) -> None:
        getattr(self, "do_" + name)()
        self.note()
        self.first_before = self.store.first_seq

    def put(self, count: int, pad: int, codec: str | None = None) -> None:
        name = ("/odom", "/tf", "../x")[len(self.puts) % 3]
        messages = [(self.t + i, json.dumps({"n": len(self.puts), "i": i, "pad": _pad(self.t + i, i * pad % 97)}))
                    for i in range(count)]  # fmt: skip
        self.t += count
        # Listed first: a put whose own group commit fails raises StoreFailedError with its
        # record handed to the OS, so it may or may not survive (an unknown outcome). One
        # entry per record: a window over the record limit is stored as parts, seq on.
        for lo, hi in split_bounds(name, [text for _, text in messages]):
            self.puts.append(Put(name, messages[lo:hi], digest(name, messages[lo:hi]), last=hi == count))
        self.store.put_window(name, messages, codec=codec)

    def do_put(self) -> None:
        self.put(1 + len(self.puts) % 3, 7)

    def do_big(self) -> None:
        """A window of several sectors, uncompressed (torn writes cut it), handed to the OS
        at once without an fsync, as when the write buffer overflows."""
        self.put(24, 31, codec="none")
        with self.store.lock:
            self.store.active.flush()

    def do_split(self) -> None:
        """A window over the record limit (lowered to SPLIT_RAW), stored as parts with the
        PART flag, each handed to the OS as its own write (as parts over the 1 MiB write
        buffer are), uncompressed: crashes fall between the parts and inside them."""
        saved = encode.MAX_RECORD_RAW, segment.WRITE_BUFFER
        encode.MAX_RECORD_RAW, segment.WRITE_BUFFER = SPLIT_RAW, 1
        try:
            self.put(24, 31, codec="none")
        finally:
            encode.MAX_RECORD_RAW, segment.WRITE_BUFFER = saved

    def do_sync(self) -> None:
        self.store.sync()

    def do_reopen(self) -> None:
        self.store.close()
        self.store = cclogfs.open_store(DIR, **self.opts)

    def reopen_after_crash(self) -> None:
        """A new process on the same page cache: it holds what the old one handed the OS."""
        self.store = cclogfs.open_store(DIR, **self.opts)
        seqs = [w.seq for w in self.store.query()]
        end = seqs[-1] + 1 if seqs else self.store.first_seq
        del self.puts[end:]

    def do_kill(self) -> None:
        kill(self.store)
        self.reopen_after_crash()

    def do_seal(self) -> None:
        self.store.seal()

    def do_age(self) -> None:
        self.store.rewrite(age_window)

    def do_drop(self) -> None:
        self.store.drop_oldest()

    def do_failsync(self) -> None:
        """The next fsync fails (the put's group commit, or the sync's), then a reopen."""
        self.fs.fail_fsyncs.add(self.fs.fsyncs + 1)
        try:
            self.do_put()
            self.store.sync()
        except StoreFailedError:
            pass
        try:
            self.store.close()  # a failed store commits nothing more
        except StoreFailedError:  # the failure hit close's checkpoint
            pass
        self.reopen_after_crash()

    def finish(self) -> Trace:
        self.store.close()
        self.note()
        self.trace.ops = self.fs.ops
        return self.trace


def kill(store) -> None:
    """kill -9: nothing of the process runs any more; what it handed the OS stays."""
    with store.lock:
        store._closed = True
        store._wake.notify_all()
    if store._flusher is not None:
        store._flusher.join()
    store.fs.unlock(store._lock_fd)


def age_window(window):
    """Keep every other message, as aging does, flagged AGED."""
    messages = list(window.messages())[::2]
    return Replacement(messages, dict(window.meta, aged={"downsampled": 2}), flags=int(RecordFlag.AGED))


def run_steps(steps, sync_every_bytes) -> Trace:
    w = Workload(sync_every_bytes)
    w.do_put()
    w.do_sync()
    w.note()
    w.trace.begin = len(w.fs.ops)
    for s in steps:
        w.step(s)
    return w.finish()


# -- acknowledgements -------------------------------------------------------------------------


def acked_per_op(ops, seed: dict[str, bytes] | None = None) -> list[int]:
    """Per op, how many puts an fsync had made durable by then: at each fsync of a segment,
    every record of its gapless prefix (a sync, a group commit, a close, recovery's rewrite)."""
    model, out, acked = DiskModel(), [], 0
    model.seed(seed or {})
    for op in ops:
        model.apply(op)
        if op[0] == "fsync" and op[1].endswith(".seg") and "-" not in os.path.basename(op[1]):
            name = os.path.basename(op[1])
            acked = max(acked, prefix_end(bytes(model.inodes[model.names[name]].current), int(name[:20])))
        out.append(acked)
    return out


def prefix_end(data: bytes, first_seq: int) -> int:
    end = first_seq
    try:
        for rec in records(BytesAt(data), SEGMENT_HEADER_SIZE, len(data), first_seq):
            end = rec.header.seq + 1
    except UnfinishedPut as err:  # durable parts of a put whose last part is not: none of it is
        end = err.first[1]
    except RecordError:
        pass
    return end


# -- opening an image -------------------------------------------------------------------------


@dataclass(frozen=True)
class Seen:
    """What a crash image opened to (or the error it raised)."""

    error: str = ""
    first_seq: int = 0
    windows: tuple = ()  # (seq, name, digest, aged stamps or None, salvaged seq or None)


def observe(files: dict[str, bytes], then_write: bool = True) -> Seen:
    """Open the image as the writer and read everything; with `then_write`, also put a
    window, sync, and reopen: the recovered store must take writes and reopen clean."""
    fs = MemFileSystem.holding(DIR, files)
    opts = dict(OPTS, sync_every_bytes=None, fs=fs)
    try:
        with cclogfs.open_store(DIR, **opts) as store:
            windows = tuple(_seen(w) for w in sorted(store.query(), key=lambda w: w.seq))
            first = store.first_seq
            if then_write:
                store.put_window("/after", [(10**15, "{}")])
                store.sync()
        if not then_write:
            return Seen("", first, windows)
        with cclogfs.open_store(DIR, **opts) as store:
            if not store.recovery.clean:
                return Seen(f"the second open recovered again: {store.recovery.problems}")
            if sum(1 for _ in store.query()) != len(windows) + 1:
                return Seen("the put after recovery is not there after a reopen")
    except Exception as err:  # noqa: BLE001 - any error is a finding, named
        return Seen(f"{type(err).__name__}: {err}")
    return Seen("", first, windows)


def _seen(w) -> tuple:
    messages = list(w.messages())
    salvaged = w.meta.get("salvaged", {}).get("seq")
    return (w.seq, w.name, digest(w.name, messages), tuple(t for t, _ in messages) if w.aged else None, salvaged)


def violation(seen: Seen, ref: tuple, must: int, firsts: frozenset) -> str | None:
    """Why `seen` breaks the contract for a crash at a point where the store held a prefix
    of `ref`, `must` of them durable, the log starting at one of `firsts`; None if it holds."""
    if seen.error:
        return seen.error
    if seen.first_seq not in firsts:
        return f"the log starts at seq {seen.first_seq}, not at one of {sorted(firsts)}"
    for i, w in enumerate(seen.windows):
        if w[0] != seen.first_seq + i:
            return f"a hole or reordering: seq {w[0]} where {seen.first_seq + i} belongs"
    own = [w for w in seen.windows if w[4] is None]
    for seq, name, dig, stamps, _s in own:
        if seq >= len(ref):
            return f"seq {seq} was never put (only {len(ref)} were)"
        put = ref[seq]
        if name != put.name:
            return f"seq {seq} is a window of {name}, put to {put.name}"
        if stamps is None and dig != put.digest:
            return f"seq {seq} holds other messages than were put"
        if stamps is not None and not set(stamps) <= {t for t, _ in put.messages}:
            return f"aged seq {seq} holds stamps that were never put"
    if own and not ref[own[-1][0]].last:
        return f"the log ends inside a split put: seq {own[-1][0]} is a part whose window goes on"
    # `fsck --repair` appends what it salvaged from a side file (meta "salvaged"): copies of
    # puts, after the prefix, and synced by the repair's own sync.
    end = seen.first_seq + len(seen.windows)
    if end < must:
        return f"lost synced puts: the log ends at seq {end}, {must} were synced"
    for seq, name, dig, _stamps, salvaged in seen.windows[len(own):]:
        if salvaged is None or salvaged >= len(ref) or dig != digest(name, ref[salvaged].messages):
            return f"seq {seq} after the prefix is not a salvaged copy of a put"
    return None


# -- exploring --------------------------------------------------------------------------------


@dataclass
class Tally:
    images: int = 0
    states: int = 0  # distinct images opened
    written: int = 0  # of which: also written to and reopened (every WRITE_EVERY-th)
    nested: int = 0  # of which: crashes during a recovery or repair
    violations: list = field(default_factory=list)
    seen: dict = field(default_factory=dict)

    def check(self, files: dict[str, bytes], ref, must, firsts, where: str) -> Seen:
        self.images += 1
        h = hashlib.blake2b(digest_size=16)
        for name in sorted(files):
            h.update(b"%s\0%d\0" % (name.encode(), len(files[name])) + files[name])
        key = h.digest()
        seen = self.seen.get(key)
        if seen is None:
            write = self.states % WRITE_EVERY == 0
            seen = self.seen[key] = observe(files, write)
            self.states += 1
            self.written += write
        problem = violation(seen, ref, must, firsts)
        if problem and len(self.violations) < 20:
            self.violations.append(f"{where}: {problem}")
        elif problem:
            self.violations.append(None)
        return seen


def explore(trace: Trace, tally: Tally, rng: random.Random, label: str, nested_every: int = 0) -> None:
    """Every mode at every boundary from `trace.begin` on, plus MIXED mixed images each."""
    # Images of two runs never coincide (each store has its own id and segment creation
    # times), so identical images are looked for within one run: memory stays bounded.
    tally.seen.clear()
    acked = acked_per_op(trace.ops)
    model = DiskModel()
    for k, op in enumerate(trace.ops):
        model.apply(op)
        if k < trace.begin - 1:
            continue
        ref, must, firsts = trace.refs[k], acked[k], trace.first_seqs[k]
        images = [model.image(rng, mode) for mode in MODES] if model.pending() else [model.image(rng, "lost")]
        images += [model.image_mixed(rng) for _ in range(MIXED if model.pending() else 0)]
        for files in images:
            if "MANIFEST" not in files:  # before the store was first made: nothing to hold
                if must:
                    tally.violations.append(f"{label} op {k}: the store vanished with {must} puts synced")
                continue
            before = tally.states
            tally.check(files, ref, must, firsts, f"{label} op {k} {op[0]}")
            if nested_every and tally.states > before and rng.randrange(nested_every) == 0:
                crash_recovery(files, ref, must, firsts, tally, rng, f"{label} op {k} recovery")


def crash_recovery(files, ref, must, firsts, tally: Tally, rng: random.Random, label: str) -> None:
    """Crash again at every boundary of the recovery that opens `files`, then of a repair."""
    fs = RecordingMemFileSystem({os.path.join(DIR, n): d for n, d in files.items()}, {DIR})
    try:
        cclogfs.open_store(DIR, **dict(OPTS, sync_every_bytes=None, fs=fs)).close()
        repair_store(DIR, fs=fs)
    except Exception:  # noqa: BLE001 - the outer check names this image's error
        return
    model = DiskModel()
    model.seed(files)
    acked = acked_per_op(fs.ops, files)
    for k, op in enumerate(fs.ops):
        model.apply(op)
        if not model.pending():
            continue
        for files2 in [model.image(rng, mode) for mode in MODES] + [model.image_mixed(rng)]:
            before = tally.states
            tally.check(files2, ref, max(must, acked[k]), firsts, f"{label} op {k} {op[0]}")
            tally.nested += tally.states - before


def check_workloads(workloads, seed: int = 0, nested_every: int = 8, group_bytes=(None, 700)) -> Tally:
    """Explore the given step sequences, each without and with group commits by size; a
    workload that raises is a violation too."""
    tally, rng = Tally(), random.Random(seed)
    for steps, sync_every_bytes in itertools.product(workloads, group_bytes):
        try:
            explore(run_steps(steps, sync_every_bytes), tally, rng, ",".join(steps) or "start", nested_every)
        except Exception as err:  # noqa: BLE001 - a store error in the workload itself
            tally.violations.append(f"{','.join(steps)}: the workload raised {type(err).__name__}: {err}")
    return tally


def ace_workloads(max_len: int = 3):
    for n in range(max_len + 1):
        yield from itertools.product(STEPS, repeat=n)


def run(states: int, seed: int, long_len: int = 20, nested_every: int = 8, out=sys.stdout,
        time_limit: float | None = None) -> Tally:  # fmt: skip
    """Check at least `states` distinct crash states: every workload of up to 3 steps (each
    with and without automatic group commits by size), then random ones up to `long_len`
    steps, then the background threads, until there are enough."""
    tally, rng, t0 = Tally(), random.Random(seed), time.monotonic()
    for i, steps in enumerate(ace_workloads()):
        explore(run_steps(steps, (None, 700)[i % 2]), tally, rng, "ace " + ",".join(steps) or "start", nested_every)
    print(f"ace: {tally.states} states after every workload of up to 3 steps", file=out, flush=True)
    i = 0
    while tally.states < states and (time_limit is None or time.monotonic() - t0 < time_limit):
        if i % 4 == 3:
            explore(run_background(rng.randrange(2**32)), tally, rng, f"background {i}", nested_every)
        else:
            steps = [rng.choice(LONG_STEPS) for _ in range(rng.randint(4, long_len))]
            explore(run_steps(steps, rng.choice((None, 700, 2500))), tally, rng, "long " + ",".join(steps), nested_every)
        i += 1
        if i % 100 == 0:
            print(f"{tally.states} states, {len(tally.violations)} violations, {time.monotonic() - t0:.0f} s",
                  file=out, flush=True)  # fmt: skip
    return tally


def run_background(seed: int) -> Trace:
    """Puts while the group-commit thread commits on its own timer and the upkeep thread
    ages sealed segments; then a kill and more puts on the same page cache."""
    from cclogfs.upkeep import Upkeep
    from cclogfs.upkeep.policy import Policy, parse_rule

    rng = random.Random(seed)
    w = Workload(None)
    w.store.close()
    w.opts["sync_every_ms"] = 1
    w.store = cclogfs.open_store(DIR, **w.opts)
    w.note()
    w.trace.begin = len(w.fs.ops)
    upkeep = Upkeep(policy=Policy([parse_rule("1e-2")]), older_than_ns=0)
    for i in range(rng.randint(6, 14)):
        w.do_put()
        upkeep.after_put(w.store)
        time.sleep(rng.random() * 0.003)
        w.note()
    upkeep.close()
    w.note()
    w.do_kill()
    for _ in range(3):
        w.do_put()
        time.sleep(0.002)
        w.note()
    return w.finish()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--long", type=int, default=20, help="longest random workload (steps)")
    ap.add_argument("--max-s", type=float, default=None, help="stop the random workloads after this long")
    args = ap.parse_args()
    t0 = time.monotonic()
    tally = run(args.states, args.seed, args.long, time_limit=args.max_s)
    print(f"{tally.states} distinct crash states checked ({tally.images} images, {tally.nested} of the "
          f"states crashed a recovery or repair), {len(tally.violations)} violations, "
          f"{time.monotonic() - t0:.0f} s")  # fmt: skip
    for v in tally.violations[:20]:
        print("  " + str(v))
    return 1 if tally.violations else 0


if __name__ == "__main__":
    sys.exit(main())
