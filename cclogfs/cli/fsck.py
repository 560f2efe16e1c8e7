"""`cclog fsck STORE`: check a store; exit 1 when data is damaged."""

from __future__ import annotations

import argparse
import json
import os
import sys

from .common import add_record_limit, cli_words


EXAMPLES = """examples:
  cclog fsck out/demo/store
  cclog fsck out/demo/store --deep      # also decode every window
  cclog fsck out/demo/store --repair     # rebuild indexes, cut a torn tail, salvage side files
  cclog fsck out/demo/store --repair --discard-damaged   # and drop named damage for good
exit status without --repair: 0 clean (warnings allowed), 1 damaged data found, 8 nothing to
  check (the path is missing, not a directory, or a directory that holds no store).
exit status with --repair (as e2fsck): 0 clean, nothing to do; 1 repaired, now clean;
  4 damage left (named in the manifest or quarantined: reads refuse it until
  --discard-damaged; or a damaged segment header whose first seq its name, the manifest
  and its records do not all prove, kept as it is); 8 operational error (the store could
  not be opened or written, or another writer holds it).
"""


DESCRIPTION = (
    "Check every record's header CRC and payload hash, sequence "
    "continuity, the manifest's statistics and the time indexes. "
    "Changes nothing, unless --repair is given."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("store", help="store directory")
    p.add_argument("--deep", action="store_true", help="decode every window's messages too")
    add_record_limit(p)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--repair", action="store_true",
                   help="repair: rebuild indexes and damaged segment headers its records prove, cut an unsynced "
                        "torn tail, salvage intact records of side files into the store, quarantine damaged "
                        "bytes (exit 0/1/4/8, see below)")  # fmt: skip
    p.add_argument("--discard-damaged", action="store_true",
                   help="with --repair: drop the damage named in the manifest and the quarantined bytes; "
                        "the only way they are ever dropped")  # fmt: skip


def repair(args: argparse.Namespace) -> int:
    from ..errors import CclogError
    from ..store import repair_store

    try:
        report = repair_store(args.store, discard_damaged=args.discard_damaged)
    except (CclogError, OSError) as err:
        print(f"cclog: error: cannot repair {args.store}: {cli_words(str(err))}", file=sys.stderr)
        return 8
    for line in report.actions:
        print(f"repaired: {line}")
    for line in report.damage_left:
        print(f"damage left: {line}")
    for line in report.unproven:
        print(f"not repaired: {line}")
    state = {0: "clean, nothing to repair", 1: "repaired, now clean",
             4: "damage left (`--discard-damaged` drops it)"}[report.exit_code]  # fmt: skip
    if report.unproven:  # not named damage: discarding would not make the store clean
        state = "damage left that repair cannot prove how to mend (kept as it is; see 'not repaired')"
    print(f"{report.path}: {state}")
    return report.exit_code


def _not_a_store(path: str) -> str | None:
    """Why `path` holds no store at all (None when it may: a manifest or segment is there)."""
    from ..store.format import MANIFEST, parse_seq_name

    if not os.path.lexists(path):
        return f"{path} does not exist"
    if not os.path.isdir(path):
        return f"{path} is not a directory, so not a cclogfs store"
    names = os.listdir(path)
    if MANIFEST in names or any(parse_seq_name(n) for n in names):
        return None
    return f"{path} holds no cclogfs store (no {MANIFEST} and no segment files)"


def run(args: argparse.Namespace) -> int:
    if args.discard_damaged and not args.repair:
        print("cclog: error: --discard-damaged needs --repair", file=sys.stderr)
        return 2
    if args.repair:
        return repair(args)
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..store import check_store

    problem = _not_a_store(args.store)
    if problem:  # nothing to check is not damage: say what the path is instead of DAMAGED
        print(f"cclog: error: {problem}", file=sys.stderr)
        return 8

    report = check_store(args.store, deep=args.deep)
    if args.json:
        print(json.dumps({"path": report.path, "segments": report.segments, "records": report.records,
                          "messages": report.messages, "decoded": report.decoded, "aged": report.aged,
                          "findings": [vars(f) for f in report.findings]}, indent=2))  # fmt: skip
    else:
        for finding in report.findings:
            print(cli_words(str(finding)))
        state = "DAMAGED" if report.errors else "clean"
        deep = f", {report.decoded} windows decoded" if args.deep else ""
        deep += f", {report.aged} aged windows" if report.aged else ""
        print(f"{report.path}: {state}: {report.segments} segments, {report.records} records, "
              f"{report.messages} messages{deep}, {len(report.errors)} errors, "
              f"{len(report.findings) - len(report.errors)} warnings")
    return 1 if report.errors else 0
