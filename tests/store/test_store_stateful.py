"""Model-based test: random puts, syncs, queries and reopens against an in-memory model."""

import json
import shutil
import tempfile

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

import cclogfs

NAMES = st.sampled_from(["/odom", "/tf", "../../etc", "\u00e9", "/a/b"])
JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda kids: st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=4), kids, max_size=3),
    max_leaves=8,
)
TEXTS = JSON_VALUES.map(json.dumps) | st.sampled_from(['{"a":1.0}', " [1e5, -0.0] ", '"\\ud83d\\ude00"', "NaN"])


class StoreMachine(RuleBasedStateMachine):
    @initialize(codec=st.sampled_from(["columnar", "zstd", "none", "lzma"]), segment_bytes=st.sampled_from([4096, 1 << 20]))
    def open(self, codec, segment_bytes):
        self.dir = tempfile.mkdtemp()
        self.opts = dict(codec=codec, segment_bytes=segment_bytes, sync_every_ms=None, sync_every_bytes=3000)
        self.store = cclogfs.open_store(self.dir + "/s", create=True, **self.opts)
        self.model = []  # (name, start, end, messages, meta) in put order; seq = position
        self.t = 0

    @rule(name=NAMES, texts=st.lists(TEXTS, min_size=1, max_size=12), gap=st.integers(-50, 50),
          steps=st.lists(st.integers(0, 20), min_size=12, max_size=12))  # fmt: skip
    def put(self, name, texts, gap, steps):
        self.t = max(0, self.t + gap)  # windows of a stream may start before earlier ones end
        stamps = [self.t + sum(steps[: i + 1]) for i in range(len(texts))]
        messages = list(zip(stamps, texts))
        meta = {"n": len(self.model)}
        receipt = self.store.put_window(name, messages, meta=meta)
        assert receipt.seq == len(self.model)
        self.model.append((name, stamps[0], stamps[-1], messages, meta))

    @rule()
    def sync(self):
        self.store.sync()

    @rule()
    def reopen(self):
        self.store.close()
        self.store = cclogfs.open_store(self.dir + "/s", **self.opts)
        assert self.store.recovery.clean

    @precondition(lambda self: self.model)
    @rule(name=st.none() | NAMES, a=st.integers(-10, 2000), span=st.integers(0, 500))
    def query(self, name, a, span):
        want = [
            (seq, m[0]) for seq, m in enumerate(self.model)
            if (name is None or m[0] == name) and m[1] <= a + span and m[2] >= a
        ]  # fmt: skip
        want.sort(key=lambda x: (self.model[x[0]][1], x[0]))
        got = list(self.store.query(name, start_ns=a, end_ns=a + span))
        assert [(w.seq, w.name) for w in got] == want
        for w in got:
            _, start, end, messages, meta = self.model[w.seq]
            assert (w.start_ns, w.end_ns, w.count, w.meta) == (start, end, len(messages), meta)
            assert list(w.messages()) == messages

    @rule()
    def reader_sees_synced(self):
        self.store.sync()
        with cclogfs.open_store(self.dir + "/s", readonly=True) as reader:
            assert [w.seq for w in sorted(reader.query(), key=lambda w: w.seq)] == list(range(len(self.model)))

    @invariant()
    def stream_stats(self):
        if not hasattr(self, "store"):
            return
        stats = self.store.streams()
        for name in {m[0] for m in self.model}:
            mine = [m for m in self.model if m[0] == name]
            assert stats[name]["windows"] == len(mine)
            assert stats[name]["messages"] == sum(len(m[3]) for m in mine)

    def teardown(self):
        if hasattr(self, "store"):
            self.store.close()
            shutil.rmtree(self.dir, ignore_errors=True)


StoreMachine.TestCase.settings = settings(max_examples=40, stateful_step_count=30, deadline=None)
TestStore = StoreMachine.TestCase
