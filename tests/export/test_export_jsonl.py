"""Windows merged back into one time-ordered JSONL stream."""

from __future__ import annotations

import io

from hypothesis import given
from hypothesis import strategies as st

from _windows import FakeWindow

from cclogfs.export import merged_messages, write_jsonl
from cclogfs.ingest import parse_line


class CountingWindow(FakeWindow):
    opened = 0

    def messages(self):
        CountingWindow.opened += 1
        return super().messages()


def test_merge_interleaves_by_stamp_keeping_window_order_on_ties():
    windows = [
        FakeWindow("/a", 0, [(1, "a1"), (5, "a5"), (5, "a5b"), (9, "a9")]),
        FakeWindow("/b", 1, [(2, "b2"), (5, "b5"), (6, "b6")]),
        FakeWindow("/a", 2, [(7, "a7")]),
    ]
    got = [(n, s, t) for n, s, t in merged_messages(windows)]
    assert [t for _, _, t in got] == ["a1", "b2", "a5", "a5b", "b5", "b6", "a7", "a9"]
    assert [t for _, _, t in merged_messages(windows, 5, 7)] == ["a5", "a5b", "b5", "b6", "a7"]
    assert list(merged_messages([])) == []


def test_windows_open_only_when_the_merge_reaches_them():
    CountingWindow.opened = 0
    windows = [CountingWindow("/a", i, [(10 * i + k, f"{i}.{k}") for k in range(3)]) for i in range(50)]
    it = merged_messages(windows)
    assert [next(it)[2] for _ in range(4)] == ["0.0", "0.1", "0.2", "1.0"]
    assert CountingWindow.opened == 2
    CountingWindow.opened = 0
    assert len(list(merged_messages(windows, end_ns=25))) == 9  # stamps 0..2, 10..12, 20..22
    assert CountingWindow.opened == 4  # the window starting at 30 ends the merge


def test_write_jsonl_lines_parse_back():
    out = io.StringIO()
    n = write_jsonl([FakeWindow("/x", 0, [(3, '{"v": 1}'), (4, '{"v":2}')])], out)
    assert n == 2
    assert [parse_line(line) for line in out.getvalue().splitlines()] == [
        ("/x", 3, '{"v": 1}', ""), ("/x", 4, '{"v":2}', ""),
    ]  # fmt: skip


@given(st.lists(st.lists(st.integers(0, 60), min_size=0, max_size=6), max_size=12),
       st.integers(0, 60), st.integers(0, 60))  # fmt: skip
def test_merge_equals_a_sort_of_every_message_whether_windows_overlap_or_not(stamps, lo, hi):
    # Windows alone in time go out without the heap; the order must be the same as the
    # heap's: by stamp, then window order, then message order.
    windows = [FakeWindow(f"/{i % 3}", i, [(s, f"{i}.{k}") for k, s in enumerate(sorted(w))])
               for i, w in enumerate(sorted(stamps, key=lambda w: min(w, default=0)))]  # fmt: skip
    windows = [w for w in windows if w.msgs]
    every = sorted((s, i, k, w.name, t) for i, w in enumerate(windows) for k, (s, t) in enumerate(w.msgs))
    assert list(merged_messages(windows)) == [(n, s, t) for s, _i, _k, n, t in every]
    assert list(merged_messages(windows, lo, hi)) == [(n, s, t) for s, _i, _k, n, t in every if lo <= s <= hi]
