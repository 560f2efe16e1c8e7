"""A window that grows back after a part of it was stored, read back end to end.

Smart logging stores an open window in parts (`cut` every --window-max-s, or past
`max_part` messages of a topic). A later flag whose evidence reaches further back than
the window's start extends it back (`WindowBuilder._reach_back`), and what it takes back
goes into the window's next part: that part starts before parts stored earlier, so seq
order is not time order (docs/CLASSIFIER.md). `cat`, `export --mcap` and `play` must
still give every message of the windows once, in time order, byte for byte; they get
windows from `store.query`, in (start, seq) order, which `merged_runs` relies on.
"""

from __future__ import annotations

import json
from collections import defaultdict
from typing import NamedTuple

import pytest
from mcap.reader import make_reader

import cclogfs
from cclogfs.classifier.windows import WindowBuilder
from cclogfs.cli import main
from cclogfs.export.jsonl import merged_messages
from cclogfs.jsontext.lines import format_line
from cclogfs.pipeline import record
from cclogfs.play.pace import paced, store_messages

MS = 1_000_000
S = 1000 * MS


class Msg(NamedTuple):
    topic: str
    stamp_ns: int
    text: str


def source() -> list[Msg]:
    """/odom and /imu at 100 Hz (/imu 5 ms after), /scan at 20 Hz on odometry stamps (equal
    stamps across topics), /tf_static once; texts in uneven layouts, kept byte for byte."""
    out = [Msg("/tf_static", 1 * S, '{"transforms": [ {"child": "laser"} ]}')]
    for k in range(100, 601):  # 1.00 .. 6.00 s
        t = k * 10 * MS
        out.append(Msg("/odom", t, f'{{"k":{k}, "x": {k / 7:.4f} ,"frame":"odom"}}'))
        out.append(Msg("/imu", t + 5 * MS, f'{{ "k": {k},"w":[{k % 3}, -0.50,1e-3]}}'))
        if k % 5 == 0:
            out.append(Msg("/scan", t, f'{{"k": {k}, "ranges": [1.5, null, {k}]}}'))
    return out


class ScriptedFlags:
    """The smart logger's window policy (`WindowBuilder`, seconds mode, lookback) with the
    detector's flags given by the test: {odometry stamp: lookback_ns}. `cuts`: odometry
    stamps after which the open window is cut, as the pipeline's --window-max-s timer does.
    Keeps every window it hands out, to compare what the readers give with."""

    def __init__(self, flags: dict[int, int], cuts: set[int], **opts):
        self.b = WindowBuilder(topics=["/imu", "/scan"], **opts)
        self.flags, self.cuts = flags, cuts
        self.emitted = []

    def _kept(self, windows):
        self.emitted += windows
        return windows

    def push(self, topic, stamp_ns, text):
        flag = topic == "/odom" and stamp_ns in self.flags
        out = self.b.push(topic, stamp_ns, text, anomalous=flag, score=1.0 if flag else -1.0,
                          lookback_ns=self.flags.get(stamp_ns, 0))  # fmt: skip
        if topic == "/odom" and stamp_ns in self.cuts:
            out += self.b.cut()
        return self._kept(out)

    def cut(self):
        return self._kept(self.b.cut())

    def flush(self):
        return self._kept(self.b.flush())


# A quick flag at 2.0 s opens a window at 1.9 s (0.1 s before); parts of 8 odometry
# messages and a cut at 2.2 s store its first 0.3 s; a slow flag at 2.4 s whose evidence
# starts 0.9 s back takes the window back to 1.4 s, into its next part. A second window
# (quick flag at 4.5 s) follows.
FLAGS = {2000 * MS: 0, 2400 * MS: 900 * MS, 4500 * MS: 0}
CUTS = {2200 * MS, 4600 * MS}
OPTS = {"before_s": 0.1, "after_s": 0.3, "lookback_max_s": 1.0, "max_part": 8}
GROWN = (1400 * MS, 1900 * MS)  # the stretch taken back


@pytest.fixture(scope="module")
def grown_store(tmp_path_factory):
    """(store path, the windows' messages as (topic, stamp, text)) of a store recorded
    through the pipeline, small segments so the parts of a window lie in several. The
    windows' messages are what the readers must give, each as often as it was stored."""
    path = tmp_path_factory.mktemp("grown") / "s.store"
    policy = ScriptedFlags(FLAGS, CUTS, **OPTS)
    with cclogfs.open_store(path, create=True, segment_records=5) as store:
        record(source(), store, policy)
    kept = [(w.topic, s, t) for w in policy.emitted for s, t in w.messages]
    # Each window holds the latched /tf_static (to be read alone), so both hold its message.
    logged = [m for m in kept if m[0] != "/tf_static"]
    assert len(logged) == len(set(logged)), "the policy kept a message twice"
    assert set(kept) <= set(source())  # the source's messages, byte for byte
    return path, kept


def lines_of(messages) -> list[str]:
    return [format_line(topic, stamp, text) for topic, stamp, text in messages]


def check_once_in_time_order(got_lines: list[str], want, lo=None, hi=None) -> None:
    """`got_lines` (JSONL, with newlines) are the messages of `want` within [lo, hi], each
    once, byte for byte, in stamp order."""
    lo = -(1 << 63) if lo is None else lo
    hi = (1 << 63) if hi is None else hi
    expect = lines_of(m for m in want if lo <= m[1] <= hi)
    stamps = [json.loads(line)["stamp_ns"] for line in got_lines]
    assert stamps == sorted(stamps), "not in time order"
    assert sorted(got_lines) == sorted(expect), "a message lost, added or changed"
    assert len(got_lines) == len(expect), "a message given twice"


def test_the_store_holds_a_part_that_starts_before_a_part_stored_earlier(grown_store):
    """The case under test exists: seq order is not time order for a window, with windows
    of other streams stored between its parts, and its parts in several segments."""
    path, _ = grown_store
    with cclogfs.open_store(path, readonly=True) as store:
        windows = sorted(store.query(), key=lambda w: w.seq)
        parts = defaultdict(list)
        for w in windows:
            parts[w.name, w.meta["window_id"]].append(w)
        odom = parts["/odom", f"w{1900 * MS}"]
        starts = [w.start_ns for w in odom]
        assert starts != sorted(starts)
        back = next(w for w in odom if w.start_ns == GROWN[0])
        assert any(w.start_ns > back.start_ns for w in odom if w.seq < back.seq)
        assert any(w.name != "/odom" and w.start_ns > back.start_ns for w in windows if w.seq < back.seq)
        assert len({w._segment.path for w in odom}) > 1
        imu = [w.start_ns for w in parts["/imu", f"w{1900 * MS}"]]
        assert imu != sorted(imu)  # the other topics grow back too (`back_other`)


def test_query_yields_windows_in_start_order_not_seq_order(grown_store):
    path, _ = grown_store
    with cclogfs.open_store(path, readonly=True) as store:
        for lo, hi in [(None, None), (GROWN[0], GROWN[1]), (1600 * MS, 2100 * MS)]:
            got = [(w.start_ns, w.seq) for w in store.query(start_ns=lo, end_ns=hi)]
            assert got == sorted(got)
            assert [s for _, s in got] != sorted(s for _, s in got)  # seq order would differ


# --start/--end at the edges of the stretch taken back, inside it, across the part stored
# earlier (1.9-2.2 s), and across the whole window.
RANGES = [
    (None, None),
    (GROWN[0], GROWN[1]),
    (GROWN[0] + 5 * MS, GROWN[1] - 5 * MS),
    (1550 * MS, 1750 * MS),
    (1800 * MS, 2000 * MS),
    (1700 * MS, 2250 * MS),
    (1900 * MS, 2200 * MS),
    (1000 * MS, 1500 * MS),
    (2100 * MS, 4700 * MS),
]


@pytest.mark.parametrize("lo, hi", RANGES)
def test_cat_gives_every_message_once_in_time_order(grown_store, capsys, lo, hi):
    path, want = grown_store
    args = ["cat", str(path)]
    args += [] if lo is None else ["--start", f"{lo}ns", "--end", f"{hi}ns"]
    capsys.readouterr()
    assert main(args) == 0
    check_once_in_time_order(capsys.readouterr().out.splitlines(True), want, lo, hi)


def test_cat_of_some_topics_gives_their_messages_in_time_order(grown_store, capsys):
    path, want = grown_store
    for topics in (["/odom"], ["/imu", "/odom"], ["/scan", "/imu"]):
        capsys.readouterr()
        assert main(["cat", str(path), *(a for t in topics for a in ("--topic", t))]) == 0
        check_once_in_time_order(capsys.readouterr().out.splitlines(True), [m for m in want if m[0] in topics])


@pytest.mark.parametrize("lo, hi", [(None, None), (GROWN[0], GROWN[1]), (1700 * MS, 2250 * MS)])
def test_export_mcap_in_log_time_order(grown_store, tmp_path, lo, hi):
    """Read in log-time order (what Foxglove, `ros2 bag play` and rosbags do), the MCAP
    holds the windows' messages once, in time order, byte for byte. In file order too: the
    export merges the windows by stamp (`merged_runs`), so that each channel's sequence
    numbers increase over time (before, it wrote window after window)."""
    path, want = grown_store
    out = tmp_path / "out.mcap"
    rng = [] if lo is None else ["--start", f"{lo}ns", "--end", f"{hi}ns"]
    assert main(["export", str(path), "--mcap", str(out), "--encoding", "json", *rng]) == 0
    with open(out, "rb") as f:
        by_time = [format_line(c.topic, m.log_time, m.data.decode())
                   for _, c, m in make_reader(f).iter_messages(log_time_order=True)]  # fmt: skip
    check_once_in_time_order(by_time, want, lo, hi)
    with open(out, "rb") as f:
        in_file = [format_line(c.topic, m.log_time, m.data.decode())
                   for _, c, m in make_reader(f).iter_messages(log_time_order=False)]  # fmt: skip
    check_once_in_time_order(in_file, want, lo, hi)


def test_play_gives_every_message_once_in_time_order(grown_store, capsys):
    """The pacing iterator over the store, with a fake clock, and `cclog play` itself."""
    path, want = grown_store
    with cclogfs.open_store(path, readonly=True) as store:
        for lo, hi in [(None, None), (GROWN[0], GROWN[1]), (1700 * MS, 2250 * MS)]:
            now, got, played = [0.0], [], []
            for m in paced(store_messages(store, None, lo, hi), clock=lambda: now[0],
                           sleep=lambda s: now.__setitem__(0, now[0] + s)):  # fmt: skip
                got.append(m)
                played.append(now[0])
            check_once_in_time_order(lines_of(got), want, lo, hi)
            # Each message at its recorded time: the clock never had to go back.
            assert played == pytest.approx([(s - got[0][1]) / 1e9 for _, s, _ in got])
    capsys.readouterr()
    assert main(["play", str(path), "--rate", "1000", "--start", f"{GROWN[0]}ns", "--end", f"{2250 * MS}ns"]) == 0
    check_once_in_time_order(capsys.readouterr().out.splitlines(True), want, GROWN[0], 2250 * MS)


def test_merged_runs_needs_windows_in_start_order(grown_store):
    """The worst case for the merge: the windows in the order they were stored (seq), so
    a part that starts at 1.4 s comes after parts that start later. The merge opens a
    window once it reaches the window's start, so given seq order it would have given
    later messages before it; it refuses, rather than give them out of order."""
    path, _ = grown_store
    with cclogfs.open_store(path, readonly=True) as store:
        by_seq = sorted(store.query(), key=lambda w: w.seq)
        with pytest.raises(ValueError, match="start order"):
            list(merged_messages(by_seq))


@pytest.mark.parametrize("encoding", ["json", "auto"])
def test_export_mcap_sequence_increases_with_log_time_per_channel(grown_store, tmp_path, encoding):
    """MCAP (spec, Message): `sequence` should be "unique per channel and increasing over
    time". Numbered in file order, window after window, a window whose parts overlap in
    time (a grown-back part, other topics' parts) gave sequences that go back in log-time
    order, which readers that check for drops take for lost or reordered messages."""
    path, _ = grown_store
    out = tmp_path / "out.mcap"
    assert main(["export", str(path), "--mcap", str(out), "--encoding", encoding]) == 0
    with open(out, "rb") as f:
        read = [(c.topic, m.log_time, m.sequence) for _, c, m in make_reader(f).iter_messages(log_time_order=True)]
    by_channel = defaultdict(list)
    for topic, log_time, sequence in read:
        by_channel[topic].append((log_time, sequence))
    for topic, got in by_channel.items():
        sequences = [s for _, s in got]
        assert sequences == sorted(sequences), f"{topic}: sequence goes back in log-time order"
        assert len(set(sequences)) == len(sequences), f"{topic}: a sequence given twice"
