"""What the subcommands share: argument types, the store selection of `cat` and `export`,
labels files, the progress counter, and the text formatting they print with. Subcommand
modules import this one, never each other. Only light imports here: `cclog --help` loads
every subcommand module."""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from pathlib import Path
from typing import TextIO

from ..errors import CorruptionError, InvalidInputError
from ..textfmt import human_bytes, iso_ns, table
from ..times import parse_time

__all__ = ["Progress", "add_selection", "human_bytes", "iso_ns", "load_labels", "parse_size", "selected_windows",
           "table", "time_arg"]  # fmt: skip

_SIZE = re.compile(r"(\d+(?:\.\d*)?)\s*(B|KB|MB|GB|TB|KiB|MiB|GiB|TiB)?", re.IGNORECASE)
_SIZE_UNIT = {"b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9, "tb": 10**12,
              "kib": 2**10, "mib": 2**20, "gib": 2**30, "tib": 2**40}  # fmt: skip


def parse_size(text: str) -> int:
    """Bytes for "500MB", "20GiB", "1048576" (no unit: bytes)."""
    m = _SIZE.fullmatch(text.strip())
    if m is None:
        raise InvalidInputError(f"Size {text!r} is not understood; give e.g. 500MB, 20GiB or a byte count.")
    return int(float(m.group(1)) * _SIZE_UNIT[(m.group(2) or "b").lower()])


def time_arg(text: str) -> int:
    """parse_time for argparse, so a bad time is reported with its own explanation."""
    try:
        return parse_time(text)
    except InvalidInputError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_selection(p: argparse.ArgumentParser) -> None:
    """STORE, --topic, --start, --end: the arguments cat and export share."""
    p.add_argument("store", help="store directory")
    p.add_argument("--topic", action="append", metavar="T", help="only stream T (repeatable)")
    p.add_argument("--start", type=time_arg, metavar="TIME", help="from this time on")
    p.add_argument("--end", type=time_arg, metavar="TIME", help="up to this time (inclusive)")
    p.add_argument("--skip-damaged", action="store_true",
                   help="read every intact window of a damaged store; say on stderr what was skipped "
                        f"and exit {EXIT_SKIPPED} (without it, damage is an error)")  # fmt: skip


# Exit status of a reading command that skipped damaged windows (--skip-damaged): not 0,
# since the answer is partial, and not 1, since it is not a failure (docs/CLI.md).
EXIT_SKIPPED = 3


class Skipped:
    """What a reading command with --skip-damaged left out: stretches the store knows are
    damaged, and windows whose record failed a check when read."""

    def __init__(self, store, args: argparse.Namespace):
        self.skip = bool(getattr(args, "skip_damaged", False))
        self.stretches = store.damage() if self.skip else []
        self.windows: list[str] = []

    def report(self) -> int:
        """Say on stderr what was skipped; the exit status."""
        if not (self.stretches or self.windows):
            return 0
        from ..store.store import describe_damage

        where = [describe_damage(d) for d in self.stretches] + self.windows
        print(f"cclog: warning: skipped {len(self.stretches)} damaged stretches and {len(self.windows)} "
              f"damaged windows: {'; '.join(where)}", file=sys.stderr)  # fmt: skip
        return EXIT_SKIPPED


def selected_windows(store, args: argparse.Namespace, skipped: Skipped | None = None):
    """The store's windows for the chosen topics and times, in start order. With
    `skipped` collecting (--skip-damaged), damaged windows are left out and noted there."""
    topics = set(args.topic or ())
    name = next(iter(topics)) if len(topics) == 1 else None
    skip = skipped is not None and skipped.skip
    for w in store.query(name, start_ns=args.start, end_ns=args.end, skip_damaged=skip):
        if topics and w.name not in topics:
            continue
        if skip:
            try:
                w.check()
            except CorruptionError as err:
                skipped.windows.append(f"{os.path.basename(err.path)} at offset {err.offset}: {err.reason}")
                continue
        yield w


def load_labels(path: str | None):
    """The labelled events of a run from a JSON file (None without a path)."""
    if path is None:
        return None
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise InvalidInputError(f"cannot read labels {path}: {err}") from err


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
