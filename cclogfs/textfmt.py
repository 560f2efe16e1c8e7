"""Plain-text report helpers shared by the CLI and the demo: sizes, ISO times, tables."""

from __future__ import annotations

import datetime as _dt


def iso_ns(ns: int) -> str:
    """An ns timestamp as ISO-8601 UTC with milliseconds."""
    t = _dt.datetime.fromtimestamp(ns // 1_000_000_000, tz=_dt.timezone.utc)
    return t.strftime("%Y-%m-%dT%H:%M:%S") + f".{ns % 1_000_000_000 // 1_000_000:03d}Z"


def human_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError


def table(rows: list[list[str]], header: list[str]) -> str:
    """A plain text table; numbers right-aligned."""
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]

    def line(r):
        cells = []
        for i, cell in enumerate(r):
            cell = str(cell)
            numeric = cell[:1].isdigit() or cell[:1] in "-." and cell[1:2].isdigit()
            cells.append(cell.rjust(widths[i]) if numeric and r is not header else cell.ljust(widths[i]))
        return "  ".join(cells).rstrip()

    sep = "  ".join("-" * w for w in widths)
    return "\n".join([line(header), sep, *(line(r) for r in rows)])
