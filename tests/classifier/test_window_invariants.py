"""What a logging window promises in seconds mode (issue 15, sixth pass), whatever the
flags, scores and lookbacks: nothing logged twice, windows in order and apart by more than
the merge gap, and every message within a flag's context (`before_s` ahead of where its
evidence starts, up to `after_s` after it) stored, so an event whose messages are all within
flagged context is stored whole, also where a later flag of a window reaches further back
than the flag that opened it."""

from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.classifier.windows import WindowBuilder

MS = 1_000_000

# A trigger message: (stamp step ms, score, lookback ms). Scores above 0 are anomalous,
# between the hold level and 0 hold an open window.
message = st.tuples(st.sampled_from([10, 10, 10, 33, 100, 0, 700]),
                    st.sampled_from([-1.0] * 10 + [-0.2, -0.2, 0.4]),
                    st.sampled_from([0, 550, 550, 4000, 8000]))  # fmt: skip
options = st.fixed_dictionaries({
    "before_s": st.sampled_from([0.0, 0.1, 0.5, 1.0, 2.0]),
    "after_s": st.sampled_from([0.0, 0.05, 0.5, 1.0]),
    "lookback_max_s": st.sampled_from([0.0, 0.5, 2.0, 8.0]),
    "merge_s": st.sampled_from([0.0, 0.3, 3.0, 4.5]),
    "hold_score": st.sampled_from([None, -0.3]),
})  # fmt: skip


def run(opts, steps):
    """(stamps, flags, scores, lookbacks, windows as lists of message indices)."""
    b = WindowBuilder(**opts)
    stamps, out, t = [], [], 0
    for k, (step, score, back) in enumerate(steps):
        t += step * MS
        stamps.append(t)
        out += b.push("/odom", t, str(k), anomalous=score > 0, score=score, lookback_ns=back * MS)
    out += b.flush()
    windows = [[int(x) for _, x in w.messages] for w in out if w.topic == "/odom"]
    return stamps, steps, windows


@settings(max_examples=300, deadline=None)
@given(opts=options, steps=st.lists(message, max_size=150))
def test_windows_keep_every_flag_context_once(opts, steps):
    stamps, steps, windows = run(opts, steps)
    logged = [i for w in windows for i in w]
    assert len(logged) == len(set(logged)), "a message logged twice"
    assert logged == sorted(logged), "windows out of order"
    before, after = int(opts["before_s"] * 1e9), int(opts["after_s"] * 1e9)
    lookback_max = int(opts["lookback_max_s"] * 1e9)
    kept = set(logged)
    for i, (_, score, back) in enumerate(steps):
        if score <= 0:
            continue
        reach = min(back * MS, lookback_max)
        lo, hi = stamps[i] - reach - before, stamps[i] + after
        need = [j for j, t in enumerate(stamps) if lo <= t < hi or j == i]
        assert kept.issuperset(need), f"flag {i}: context {lo}..{hi} not all stored"
    for w in windows:  # each window holds a flag and starts no earlier than their contexts
        flags = [i for i in w if steps[i][1] > 0]
        assert flags
        assert stamps[w[0]] >= min(stamps[i] - min(steps[i][2] * MS, lookback_max) - before for i in flags)


@settings(max_examples=300, deadline=None)
@given(opts=options, steps=st.lists(message, max_size=150))
def test_windows_apart_by_more_than_the_merge_gap(opts, steps):
    """A window opens apart from the one before when its first flag's context comes no
    nearer than merge_s to it (a later flag may still extend it back, up to the one before)."""
    stamps, steps, windows = run(opts, steps)
    before, merge = int(opts["before_s"] * 1e9), int(opts["merge_s"] * 1e9)
    lookback_max = int(opts["lookback_max_s"] * 1e9)
    for w1, w2 in zip(windows, windows[1:]):
        first = next(i for i in w2 if steps[i][1] > 0)
        start = stamps[first] - min(steps[first][2] * MS, lookback_max) - before
        assert start - stamps[w1[-1]] > merge, (w1[-1], w2[0])
        assert w2[0] > w1[-1]


def test_a_later_flag_reaching_before_the_window():
    """A flag whose evidence reaches further back than the flag that opened its window
    (a slow feature after a quick one) extends the window back (until the sixth pass the
    messages before the start were dropped when it opened)."""
    opts = {"before_s": 0.0, "after_s": 0.0, "lookback_max_s": 0.5, "merge_s": 0.0, "hold_score": None}
    _, _, windows = run(opts, [(10, -1.0, 0), (10, 0.4, 0), (10, 0.4, 550)])
    assert windows == [[0, 1, 2]]
