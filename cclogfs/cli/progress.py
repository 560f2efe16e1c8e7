"""A one-line progress counter on stderr, drawn only when stderr is a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Counts items; redraws at most ten times a second; silent when not on a terminal."""

    def __init__(self, label: str, *, unit: str = "msgs", stream: TextIO | None = None,
                 total: int | None = None) -> None:  # fmt: skip
        self.label, self.unit, self.total = label, unit, total
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty()
        self.count = 0
        self._t0 = self._drawn = time.monotonic()

    def __call__(self, n: int = 1) -> None:
        self.count += n
        if self.enabled and (now := time.monotonic()) - self._drawn >= 0.1:
            self._drawn = now
            self._draw(now)

    def _draw(self, now: float) -> None:
        rate = self.count / max(now - self._t0, 1e-9)
        if self.total:  # known up front (a bag's message count): how far, and the time left
            left = max(self.total - self.count, 0) / max(rate, 1e-9)
            line = (f"{self.count:,} of {self.total:,} {self.unit} ({100 * min(self.count / self.total, 1.0):.0f} %, "
                    f"{rate:,.0f}/s, {left:,.0f} s left)")  # fmt: skip
        else:
            line = f"{self.count:,} {self.unit} ({rate:,.0f}/s)"
        self.stream.write(f"\r{self.label}: {line}\x1b[K")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self._draw(time.monotonic())
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
