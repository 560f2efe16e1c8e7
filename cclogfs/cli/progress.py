"""A one-line progress counter on stderr, drawn only when stderr is a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Counts items; redraws at most ten times a second; silent when not on a terminal."""

    def __init__(self, label: str, *, unit: str = "msgs", stream: TextIO | None = None) -> None:
        self.label, self.unit = label, unit
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
        self.stream.write(f"\r{self.label}: {self.count:,} {self.unit} ({rate:,.0f}/s)\x1b[K")
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
