"""Model-based test of compaction: random puts, seals, rewrites (keep, replace, downsample,
age), drops of the oldest segment, reopens and refreshes against an in-memory model."""

import json
import shutil
import tempfile
from pathlib import Path

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

import cclogfs
from cclogfs.store import check_store
from _rewrite import leftovers, random_rewrite, state

NAMES = st.sampled_from(["/odom", "/tf", "../x"])


class CompactionMachine(RuleBasedStateMachine):
    @initialize(codec=st.sampled_from(["columnar", "zstd"]), segment_records=st.sampled_from([2, 5, 1000]))
    def open(self, codec, segment_records):
        self.dir = tempfile.mkdtemp()
        self.opts = dict(codec=codec, segment_records=segment_records, sync_every_ms=None, sync_every_bytes=None)
        self.store = cclogfs.open_store(self.dir + "/s", create=True, **self.opts)
        self.reader = cclogfs.open_store(self.dir + "/s", readonly=True)
        self.model = {}  # seq -> (seq, name, start, end, meta, flags, messages), as state() lists them
        self.next_seq = 0
        self.dropped = {}  # stream -> windows dropped
        self.t = 0

    @rule(name=NAMES, n=st.integers(1, 8), gap=st.integers(-20, 40))
    def put(self, name, n, gap):
        self.t = max(0, self.t + gap)
        messages = [(self.t + 3 * i, json.dumps({"seq": self.next_seq, "i": i, "x": i / 7})) for i in range(n)]
        meta = {"n": self.next_seq}
        assert self.store.put_window(name, messages, meta=meta).seq == self.next_seq
        self.model[self.next_seq] = (self.next_seq, name, messages[0][0], messages[-1][0], meta, 0, messages)
        self.next_seq += 1

    @rule()
    def seal(self):
        had = self.store.active.next_seq > self.store.active.first_seq
        assert self.store.seal() is had

    @rule(seed=st.integers(0, 2**32), pick=st.lists(st.booleans(), max_size=6) | st.none())
    def rewrite(self, seed, pick):
        firsts = [s["first_seq"] for s in self.store.manifest["segments"]]
        segments = None if pick is None else [f for f, p in zip(firsts, pick) if p]
        chosen = set(firsts if segments is None else segments)
        bounds = {s["first_seq"]: s["end_seq"] for s in self.store.manifest["segments"]}
        decided = {}
        report = self.store.rewrite(random_rewrite(seed, decided), segments=segments)
        for seq, (messages, meta, flags) in decided.items():
            old = self.model[seq]
            assert old[2] <= messages[0][0] and messages[-1][0] <= old[3]
            self.model[seq] = (seq, old[1], messages[0][0], messages[-1][0], meta, flags, messages)
        assert all(any(f <= seq < bounds[f] for f in chosen) for seq in decided)
        rewritten = {f for f in chosen if any(f <= seq < bounds[f] for seq in decided)}
        assert sorted(report.segments) == sorted(rewritten)
        assert report.replaced == len(decided)

    @rule()
    def drop_oldest(self):
        d = self.store.drop_oldest()
        if d is None:
            assert not self.store.sealed
            return
        gone = [seq for seq in self.model if seq < d.end_seq]
        assert d.first_seq == min(gone) and d.end_seq - d.first_seq == len(gone)
        for seq in gone:
            name = self.model.pop(seq)[1]
            self.dropped[name] = self.dropped.get(name, 0) + 1
        assert {k: v["windows"] for k, v in self.store.dropped()["streams"].items()} == self.dropped

    @rule()
    def reopen(self):
        self.store.close()
        self.store = cclogfs.open_store(self.dir + "/s", **self.opts)
        assert self.store.recovery.clean and not self.store.recovery.leftovers

    @rule()
    def reader_refresh(self):
        self.store.sync()
        self.reader.refresh()
        assert state(self.reader) == [self.model[s] for s in sorted(self.model)]

    @precondition(lambda self: self.model)
    @rule(name=st.none() | NAMES, a=st.integers(0, 400), span=st.integers(0, 200))
    def query(self, name, a, span):
        want = [m for m in self.model.values() if (name is None or m[1] == name) and m[2] <= a + span and m[3] >= a]
        want.sort(key=lambda m: (m[2], m[0]))
        got = list(self.store.query(name, start_ns=a, end_ns=a + span))
        assert [w.seq for w in got] == [m[0] for m in want]

    @invariant()
    def holds_the_model(self):
        if not hasattr(self, "store"):
            return
        assert state(self.store) == [self.model[s] for s in sorted(self.model)]
        stats = self.store.streams()
        for name in {m[1] for m in self.model.values()}:
            mine = [m for m in self.model.values() if m[1] == name]
            assert stats[name]["windows"] == len(mine)
            assert stats[name]["messages"] == sum(len(m[6]) for m in mine)
            assert stats[name]["aged"] == sum(1 for m in mine if m[5])
        assert self.store.first_seq == (min(self.model) if self.model else self.store.first_seq)

    def teardown(self):
        if hasattr(self, "store"):
            self.store.close()
            self.reader.close()
            assert leftovers(Path(self.dir) / "s", self.store.manifest) == []
            report = check_store(self.dir + "/s", deep=True)
            assert not report.errors, [str(f) for f in report.findings]
            shutil.rmtree(self.dir, ignore_errors=True)


CompactionMachine.TestCase.settings = settings(max_examples=100, stateful_step_count=40, deadline=None)
TestCompaction = CompactionMachine.TestCase
