"""`cclog compact STORE`: age old windows to lower fidelity, drop the oldest to fit a budget."""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

from ..errors import InvalidInputError, StoreLockedError
from ..times import parse_duration, parse_time
from .common import (
    DAMAGE_LOST,
    human_bytes,
    iso_ns,
    parse_size,
    say_dropped_damage,
    table,
    unmatched_rules_error,
)

if TYPE_CHECKING:  # the policy module loads only when aging is asked for
    from ..upkeep.policy import Policy

EXAMPLES = """examples:
  cclog compact robot.store --older-than 30d --error 1e-3
      windows that ended over 30 days before the last window of their stream: every
      float within 0.001
  cclog compact robot.store --older-than 7d --error 1e-3 --error 'pose.covariance=0.01' \\
      --error 'header.**=0' --max-rate 5 --stream /odom --stream /tf
      per-field bounds (the last matching rule wins; 0 keeps a field exact), and at most
      5 messages per second of each window
  cclog compact robot.store --budget 20GiB
      drop the oldest segments until the store fits in 20 GiB
  cclog compact robot.store --older-than 30d --error 1e-3 --budget 20GiB --dry-run
      what that would age and drop, changing nothing
exit status: 0 done, 1 error (nothing half-done: every step is crash-safe; a --budget
             under which every sealed segment would be dropped is refused, naming the
             smallest that keeps the newest), 3 done but the store is still over its budget.

Field patterns are the JSON keys joined by dots (array levels add no part): `*` matches
one key, `**` any number. Ages count back from the end of each stream's last window in log
order, in the stream's own stamps (streams may use different clocks). The budget counts
the manifest, segments and indexes. The recorder holds the store's writer lock: stop it
first (or let `cclog record --budget` drop old segments while it runs). The summary stream (/cclog/summary) stays exact unless
--stream names it.
"""

DESCRIPTION = (
    "Rewrite old windows with every float rounded within stated error bounds (and "
    "optionally fewer messages per second), then drop the oldest segments while the store "
    "is over its budget. Each aged window records how it was aged in its metadata."
)

def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..upkeep import DEFAULT_EXCLUDE

    p.add_argument("store", help="store directory (opened as its writer: stop the recorder first)")
    when = p.add_mutually_exclusive_group()
    when.add_argument("--older-than", metavar="DURATION",
                      help="age windows that ended this long before their stream's last one (e.g. 30d, 12h)")
    when.add_argument("--before", metavar="TIME", help="age windows that ended before this time")
    p.add_argument("--error", action="append", default=[], metavar="[PATTERN=]BOUND",
                   help="absolute error bound for float fields (repeatable; last match wins)")
    p.add_argument("--max-rate", type=float, metavar="HZ", help="keep at most HZ messages per second of each aged window")
    p.add_argument("--stream", action="append", default=[], metavar="PATTERN",
                   help=f"streams to age (glob, repeatable; default: all but {', '.join(DEFAULT_EXCLUDE)})")
    p.add_argument("--budget", metavar="SIZE", help="drop the oldest segments while the store is larger (e.g. 20GiB)")
    p.add_argument("--dry-run", action="store_true",
                   help="say what would be aged and dropped, change nothing (works while a recorder runs)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")


def run(args: argparse.Namespace) -> int:
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..store import open_store
    from ..upkeep import Policy, compact, parse_rule, preview

    rules = [parse_rule(r) for r in args.error]
    policy = Policy(rules, args.max_rate) if rules or args.max_rate is not None else None
    budget = parse_size(args.budget) if args.budget else None
    if policy is None and (args.older_than or args.before):
        raise InvalidInputError("--older-than/--before say which windows to age; give --error or --max-rate too.")
    if policy is None and budget is None:
        raise InvalidInputError("Nothing to do: give --error and/or --max-rate to age windows, or --budget.")
    before_ns = parse_time(args.before) if args.before else None
    older_than_ns = parse_duration(args.older_than) if args.older_than else None
    options = dict(policy=policy, before_ns=before_ns, older_than_ns=older_than_ns, streams=args.stream or None,
                   budget=budget)  # fmt: skip
    if args.dry_run:
        with open_store(args.store, readonly=True) as store:
            _check_selection(store, options)
            _check_budget(store, args.budget, budget)
            report = preview(store, **options)
    else:
        try:
            store = open_store(args.store)
        except StoreLockedError as err:
            held = str(err).split(";")[0]  # "STORE is locked by another writer (pid, host)"
            raise StoreLockedError(f"{held}; compaction needs the writer's lock: stop the recorder first "
                                   "(`cclog record --budget` drops old segments while it runs)") from None
        with store:
            _check_selection(store, options)
            _check_budget(store, args.budget, budget)
            report = compact(store, **options)
    if args.json:
        print(json.dumps(dict(report.to_dict(), dry_run=args.dry_run), indent=2))
    else:
        print(format_preview(report, policy, args) if args.dry_run else format_report(report, policy, args))
    if not args.dry_run:  # a dry run lists it with what it would drop
        say_dropped_damage(args.store, report.damage_dropped)
    return 3 if report.over_budget else 0


def _check_selection(store, options: dict) -> None:
    """Before anything ages, refuse a --stream pattern that matches no stream (it said
    "nothing to age", exit 0) and an --error rule that matches no number field of what
    would age: rounding is for good, and a misspelt field (or `msg.pose...`) was rounded by
    the general bound with exit 0."""
    from fnmatch import fnmatchcase

    from ..upkeep import unmatched_rules
    from ..upkeep.job import KEPT_STREAMS

    names = store.streams()
    for pattern in options["streams"] or ():
        matched = [name for name in names if fnmatchcase(name, pattern)]
        # it said "nothing to age (no window old enough...)", which the runs never are
        if matched and all(name in KEPT_STREAMS for name in matched):
            raise InvalidInputError(f"--stream {pattern} names only {', '.join(matched)}, which is never aged or "
                                    "compacted: it is the store's record of its runs (`record` reads their "
                                    "fingerprints to refuse a source twice), kept exact and kept by retention.")  # fmt: skip
        if not matched:  # else "nothing to age", as if all were new
            raise InvalidInputError(f"--stream {pattern} matches no stream of {store.path}; it holds "
                                    f"{', '.join(sorted(names)) or 'no streams'}.")  # fmt: skip
    policy = options["policy"]
    if policy is None or not policy.rules:
        return
    unmatched = unmatched_rules(store, policy, before_ns=options["before_ns"], older_than_ns=options["older_than_ns"],
                                streams=options["streams"])  # fmt: skip
    if unmatched:
        raise unmatched_rules_error("--error", unmatched, "nothing was aged")


def _check_budget(store, text: str | None, budget: int | None) -> None:
    """Refuse a budget under which retention would drop every sealed segment (one smaller
    than a segment): it did, with "budget met" and exit 0 when the segment being written
    fitted (3 segments of nav2_turtlebot, 7,200 messages, gone at --budget 40KiB). Checked
    on the sizes now, before what aging would save."""
    from ..upkeep.job import KEPT_STREAMS, check_budget, smallest_budget

    if budget is None:
        return
    smallest, sealed = smallest_budget(store)
    held = sum(st.get("messages", 0) for seg in sealed for name, st in seg.streams.items() if name not in KEPT_STREAMS)
    if held:
        check_budget(text, budget, smallest, "retention drops whole segments, and the newest sealed one with the one "
                     f"being written take {human_bytes(smallest)}",
                     f"the store's sealed segments ({len(sealed):,}, {held:,} messages)")  # fmt: skip


def _aging_line(policy: Policy, args: argparse.Namespace) -> str:
    if args.before:
        cutoff = f"windows ending before {args.before}"
    elif args.older_than:
        cutoff = f"windows ending over {args.older_than} before their stream's last"
    else:
        cutoff = "all windows"
    rules = ", ".join(f"{p} <= {b:g}" for p, b in policy.describe()["rules"]) or "none"
    rate = f", at most {policy.max_rate_hz:g} msg/s" if policy.max_rate_hz else ""
    return f"aging {cutoff}: error bounds {rules}{rate}"


def format_preview(report, policy: Policy | None, args: argparse.Namespace) -> str:
    """What --dry-run prints: what would happen, nothing done."""
    from ..store.store import describe_damage  # not at the top: `cclog --help` imports this module

    lines = ["dry run: nothing changed"]
    if policy is not None:
        lines.append("would be " + _aging_line(policy, args))
        rows = [[name, str(a["windows"]), str(a["messages_before"]), human_bytes(a["bytes_before"])]
                for name, a in sorted(report.aged.items())]  # fmt: skip
        lines.append(table(rows, ["stream", "windows to age", "messages", "stored now"]) if rows
                     else "nothing to age (no window old enough, or already aged this way)")  # fmt: skip
    for name, d in sorted(report.dropped.items()):
        lines.append(f"would drop {d['windows']} windows of {name} ({d['messages']} messages) from "
                     f"{iso_ns(d['start_ns'])} to {iso_ns(d['end_ns'])}")  # fmt: skip
    for d in report.damage_dropped:
        lines.append(f"would drop a segment holding damage ({describe_damage(d)}): {DAMAGE_LOST}")
    if report.budget is not None:
        saved = " (before what aging saves)" if policy is not None else ""
        lines.append(f"store: {human_bytes(report.disk_before)} -> {human_bytes(report.disk_after)}{saved}, "
                     f"budget {human_bytes(report.budget)} " + ("NOT met" if report.over_budget else "met"))  # fmt: skip
    return "\n".join(lines)


def format_report(report, policy: Policy | None, args: argparse.Namespace) -> str:
    lines = []
    if policy is not None:
        lines.append(_aging_line(policy, args))
        rows = [[name, str(a["windows"]), f"{a['messages_before']} -> {a['messages_after']}",
                 f"{human_bytes(a['bytes_before'])} -> {human_bytes(a['bytes_after'])}",
                 f"{a['bytes_after'] / a['bytes_before']:.2f}x" if a["bytes_before"] else "-"]
                for name, a in sorted(report.aged.items())]  # fmt: skip
        lines.append(table(rows, ["stream", "windows aged", "messages", "stored (rewritten segments)", "ratio"]) if rows
                     else "nothing to age (no window old enough, or already aged this way)")  # fmt: skip
    for name, d in sorted(report.dropped.items()):
        lines.append(f"dropped {d['windows']} windows of {name} ({d['messages']} messages, "
                     f"{human_bytes(d['stored_bytes'])}) from {iso_ns(d['start_ns'])} to {iso_ns(d['end_ns'])}")  # fmt: skip
    size = f"store: {human_bytes(report.disk_before)} -> {human_bytes(report.disk_after)}"
    if report.budget is not None:
        size += f" (budget {human_bytes(report.budget)}: " + ("NOT met: the active segment cannot be dropped)"
                                                             if report.over_budget else "met)")  # fmt: skip
    lines.append(size)
    return "\n".join(lines)
