"""`cclog fsck STORE`: check a store; exit 1 when data is damaged."""

from __future__ import annotations

import argparse
import json


EXAMPLES = """examples:
  cclog fsck out/demo/store
  cclog fsck out/demo/store --deep      # also decode every window
exit status: 0 clean (warnings allowed), 1 damaged data found.
"""


HELP = "verify every record, index and the manifest of a store"
DESCRIPTION = (
    "Check every record's header CRC and payload hash, sequence "
    "continuity, the manifest's statistics and the time indexes. "
    "Changes nothing."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("store", help="store directory")
    p.add_argument("--deep", action="store_true", help="decode every window's messages too")
    p.add_argument("--json", action="store_true", help="print the report as JSON")


def run(args: argparse.Namespace) -> int:
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..store import check_store

    report = check_store(args.store, deep=args.deep)
    if args.json:
        print(json.dumps({"path": report.path, "segments": report.segments, "records": report.records,
                          "messages": report.messages, "decoded": report.decoded, "aged": report.aged,
                          "findings": [vars(f) for f in report.findings]}, indent=2))  # fmt: skip
    else:
        for finding in report.findings:
            print(finding)
        state = "DAMAGED" if report.errors else "clean"
        deep = f", {report.decoded} windows decoded" if args.deep else ""
        deep += f", {report.aged} aged windows" if report.aged else ""
        print(f"{report.path}: {state}: {report.segments} segments, {report.records} records, "
              f"{report.messages} messages{deep}, {len(report.errors)} errors, "
              f"{len(report.findings) - len(report.errors)} warnings")
    return 1 if report.errors else 0
