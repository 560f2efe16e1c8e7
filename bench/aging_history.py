"""History a storage budget keeps, recording with and without aging (issue 16 item 9).

    python -m bench aging_history [--budget 192KiB] [--older-than 2min] [--error 1e-3] [FILE ...]

Each real log in ../shared/data/long (or each FILE) is recorded with `cclog record --budget`,
once with the budget alone and once with aging too (`--age-older-than`, `--age-error`). Per
run: the minutes and messages of /odom the store still holds at the end, and its size.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import shutil
import tempfile
from pathlib import Path

import cclogfs
from cclogfs.cli import main as cclog

from ._util import machine, save_json

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "long"


def kept_history(source: Path, store: Path, budget: str, aging: list[str]) -> dict:
    """Record `source` into a new `store` under `budget` (plus `aging` flags); what is kept."""
    with contextlib.redirect_stderr(io.StringIO()) as err:
        rc = cclog(["record", str(source), "--store", str(store), "--budget", budget, *aging])
    if rc != 0:
        raise SystemExit(f"cclog record {source} failed ({rc}): {err.getvalue()}")
    with cclogfs.open_store(store, readonly=True) as s:
        windows = list(s.query("/odom"))
        return {"minutes": (windows[-1].end_ns - windows[0].start_ns) / 60e9,
                "messages": sum(w.count for w in windows), "first_ns": windows[0].start_ns,
                "aged_windows": sum(w.aged is not None for w in windows), "bytes": s.data_bytes()}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path)
    ap.add_argument("--budget", default="192KiB")
    ap.add_argument("--older-than", default="2min")
    ap.add_argument("--error", default="1e-3")
    args = ap.parse_args()
    files = args.files or sorted(DATA.glob("*.mcap"))
    aging = ["--age-older-than", args.older_than, "--age-error", args.error]
    print(machine())
    print(f"budget {args.budget}; aging: older than {args.older_than}, error {args.error}")
    print(f"{'log':28} {'budget alone':>22} {'budget + aging':>22}  gain")
    rows = {}
    tmp = Path(tempfile.mkdtemp(prefix="cclog-aging-history-"))
    try:
        for f in files:
            plain = kept_history(f, tmp / f"{f.stem}.plain", args.budget, [])
            aged = kept_history(f, tmp / f"{f.stem}.aged", args.budget, aging)
            rows[f.name] = {"budget": plain, "aging": aged}
            print(f"{f.stem:28} {plain['minutes']:6.1f} min {plain['messages']:6} msgs "
                  f"{aged['minutes']:6.1f} min {aged['messages']:6} msgs  {aged['minutes'] / plain['minutes']:.2f}x")
            shutil.rmtree(tmp / f"{f.stem}.plain")
            shutil.rmtree(tmp / f"{f.stem}.aged")
        save_json("bench-aging-history.json", {"machine": machine(), "budget": args.budget, "older_than": args.older_than,
                                               "error": args.error, "runs": rows})  # fmt: skip
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
