"""cclogfs.plot.figures: the demo's PNGs (trajectory with stored windows, score over time)."""

import struct
from types import SimpleNamespace

import numpy as np

from cclogfs.plot.figures import plot_scores, plot_trajectory

NS = 1_000_000_000


def png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])  # IHDR width, height


def run(n=200):
    t = np.arange(n) * NS // 10
    angle = np.linspace(0, 2 * np.pi, n)
    return SimpleNamespace(stamp_ns=t, x=np.cos(angle), y=np.sin(angle),
                           events=[SimpleNamespace(kind="slip", start_ns=int(t[50]))])  # fmt: skip


def test_trajectory_png_and_windows_change_it(tmp_path):
    r = run()
    plain = plot_trajectory(tmp_path / "plain.png", r, [])
    kept = plot_trajectory(tmp_path / "kept.png", r, [(int(r.stamp_ns[40]), int(r.stamp_ns[90]))])
    assert png_size(plain) == png_size(kept) == (880, 770)  # 8 x 7 in at 110 dpi
    assert plain.read_bytes() != kept.read_bytes()


def test_an_event_past_the_last_stamp_is_drawn_at_the_end(tmp_path):
    r = run()
    r.events = [SimpleNamespace(kind="late", start_ns=int(r.stamp_ns[-1]) + 10 * NS)]
    assert png_size(plot_trajectory(tmp_path / "t.png", r, [])) == (880, 770)


def test_scores_png_with_windows_events_and_no_finite_score(tmp_path):
    t = np.arange(100) * NS // 10
    scores = np.sin(np.arange(100) / 5.0)
    events = [{"start_ns": int(t[20]), "end_ns": int(t[30])}]
    path = plot_scores(tmp_path / "s.png", t, scores, [(int(t[18]), int(t[35]))], events)
    assert png_size(path) == (1210, 484)  # 11 x 4.4 in at 110 dpi
    nan = plot_scores(tmp_path / "nan.png", t, np.full(100, np.nan), [], [])
    assert png_size(nan) == (1210, 484) and nan.read_bytes() != path.read_bytes()
