"""Whether two stores hold the same message records, byte for byte (issue 14, bag row).

    python3 dev.py bench store_cmp STORE_A STORE_B

Two recordings of the same file by two versions of cclogfs cannot be compared with `cmp`:
each run's record in the runs stream holds its wall-clock time and the source's path,
LOCK holds a pid, and every record header notes how far the segment was synced, which
follows the run records' sizes. This compares every other record, window by window: its
header (kind, seq, stamps, count, codec, name, config, metadata, sizes, payload hash) and
its payload bytes. Exit 1 on the first difference, which it prints.
"""

from __future__ import annotations

import re
import sys

from cclogfs.runs import hidden_by_default
from cclogfs.store import open_store


def records(path: str) -> list[tuple]:
    """(stream, header without its synced offset, payload) of every record not of a run."""
    out = []
    with open_store(path, readonly=True) as store:
        for first in store.segment_first_seqs():
            for window in store.segment_windows(first):
                if hidden_by_default(window.name):
                    continue
                header, payload = window._read()  # noqa: SLF001 - the raw record is what is compared
                out.append((window.name, re.sub(r"synced=\d+", "", repr(header)), bytes(payload)))
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python3 dev.py bench store_cmp STORE_A STORE_B", file=sys.stderr)
        return 2
    a, b = records(argv[0]), records(argv[1])
    for k, (x, y) in enumerate(zip(a, b)):
        if x != y:
            print(f"record {k} of {x[0]} differs:\n  {x[1][:300]}\n  {y[1][:300]}")
            return 1
    if len(a) != len(b):
        print(f"{len(a)} records against {len(b)}")
        return 1
    print(f"{len(a)} message records, identical")
    return 0


if __name__ == "__main__":
    sys.exit(main())
