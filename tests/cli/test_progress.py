"""Progress with a known total shows the percentage and the time left."""

import io

from cclogfs.cli.common import Progress


class Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_with_a_total_shows_percent_and_time_left(monkeypatch):
    now = [0.0]
    monkeypatch.setattr("cclogfs.cli.common.time.monotonic", lambda: now[0])
    out = Tty()
    with Progress("recording", stream=out, total=1000) as p:
        now[0] = 2.0
        p(250)  # 250 in 2 s: 125/s, 750 left: 6 s
        now[0] = 4.0
        p(250)  # 500 in 4 s: 125/s, 500 left: 4 s
    lines = [x.replace("\x1b[K", "").strip() for x in out.getvalue().split("\r") if x.strip()]
    assert lines[0] == "recording: 250 of 1,000 msgs (25 %, 125/s, 6 s left)"
    assert lines[1] == lines[-1] == "recording: 500 of 1,000 msgs (50 %, 125/s, 4 s left)"


def test_progress_without_a_total_counts():
    out = Tty()
    p = Progress("cat", stream=out)
    p(10)
    p.close()
    assert "cat: 10 msgs (" in out.getvalue() and "%" not in out.getvalue()
