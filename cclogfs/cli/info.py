"""`cclog info STORE`: what a store holds."""

from __future__ import annotations

import argparse
import json
from bisect import bisect_right

from ..errors import CorruptionError
from .common import (EXIT_SKIPPED, count_windows, cut_tail, human_bytes, iso_ns, newest_window, repair_hint, table,
                     why_records)

EXAMPLES = """examples:
  cclog info out/demo/store
  cclog info out/demo/store --json | jq '.streams["/odom"].messages'
"""


DESCRIPTION = (
    "Show what a store holds: per stream the windows, messages, time span, "
    "stored bytes, codec and the ratio against the messages' JSON; then the recording runs "
    "(/cclog/runs: when, how each ended, what it kept, source and options)."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("store", help="store directory")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def store_info(path: str) -> dict:
    """Everything `cclog info` prints, as a dict."""
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..windowcount import SUMMARY_TOPIC
    from ..runs import hidden_by_default, list_runs
    from ..store import open_store
    from ..store.store import describe_damage

    with open_store(path, readonly=True) as store:
        damage = store.damage()
        # The runs' bookkeeping is listed as runs, not counted as messages
        streams = {name: st for name, st in store.streams().items() if not hidden_by_default(name)}
        runs = list_runs(store)
        held = _Held(runs)
        # A window held in several records (a smart window's parts, ...) counts once, as
        # `record` counted it: every record's meta read (`windowcount`). The same walk
        # counts what each run's windows hold now (it was a second walk of the store).
        counted, unreadable = count_windows(held.counting(w for w in store.query(skip_damaged=True)
                                                          if w.name in streams))  # fmt: skip
        for name, st in streams.items():
            st["records"], st["windows"] = st["windows"], counted.streams.get(name, 0)
            st["stored_as"] = why_records(counted.joined, name)
            last = newest_window(store, name, st["end_ns"])
            st["codec"] = last.codec_config if last is not None else None
            st["msgtype"] = (last.meta or {}).get("msgtype", "") if last is not None else ""
            st["ratio"] = st["stored_bytes"] / st["json_bytes"] if st["json_bytes"] else None
        return {
            "summary": summary_totals(store) if SUMMARY_TOPIC in streams else None,
            "path": path,
            "store_id": store.store_id,
            "segments": store.segment_count(),
            "format_version": store.format_version,
            "first_seq": store.first_seq,
            "dropped": store.dropped(),
            "disk_bytes": store.disk_bytes(),
            "json_bytes": sum(s["json_bytes"] for s in streams.values()),
            "streams": streams,
            "runs": _runs(store, streams, damage, runs, held.held),
            "recovery": [str(p) for p in store.recovery.problems],
            # the totals leave out intact records past a cut: stored data (a side file for
            # `fsck --repair`), not a torn write, so info exits 3 as for damage
            "cut_intact": cut_tail(store),
            "damage": [describe_damage(d) for d in damage],
            "damage_repair": [repair_hint(d) for d in damage],  # what clears each stretch
            "unreadable": unreadable,  # records that failed a check when read: each counted as a window
        }


def _runs(store, streams: dict, damage: list, runs: list, held: dict[str, int]) -> list[dict]:
    """The runs as `RunInfo.as_dict` gives them, each with an end record also with
    "messages_held": the messages of its windows the store holds now. When that is fewer
    than it kept, "dropped_since" says how many went and "dropped_by" what the store shows
    could have dropped them: compaction (`compact --max-rate`, `record --age-max-rate`
    thins windows in place), retention (it drops the oldest segments) or damage (skipped).
    `held`: `_Held.held` of `runs`."""
    out = []
    for run in runs:
        r = run.as_dict()
        if run.id in held:
            r["messages_held"] = held[run.id]
            if held[run.id] < run.kept:
                causes = [cause for cause, seen in (
                    ("compaction", any(st.get("aged") for st in streams.values())),
                    ("retention", store.first_seq > run.start_seq + 1),  # a window of the run gone
                    ("damage", bool(damage))) if seen]  # fmt: skip
                r["dropped_since"] = run.kept - held[run.id]
                r["dropped_by"] = " or ".join(causes) or "unknown"
        out.append(r)
    return out


class _Held:
    """Run id -> messages the store holds of the windows the run kept (those between its
    start and end records; its recorder's summaries apart, as its end record counts them),
    for runs with an end record: from the time index's counts of the windows `counting`
    passes on, whose meta only summary windows need (to tell the recorder's own from
    messages that came in on that topic), read already by the count it passes them to."""

    def __init__(self, runs: list) -> None:
        from ..windowcount import SUMMARY_TOPIC

        self.summary_topic = SUMMARY_TOPIC
        self.spans = sorted((r.start_seq, r.end_seq, r.id) for r in runs if r.end_seq is not None and r.kept is not None)
        self.starts = [start for start, _, _ in self.spans]
        self.held = {run_id: 0 for _, _, run_id in self.spans}

    def counting(self, windows):
        """`windows` passed on, each added once the consumer is done with it."""
        for w in windows:
            yield w
            if self.spans:
                self.add(w)

    def add(self, w) -> None:
        i = bisect_right(self.starts, w.seq) - 1
        if i < 0 or w.seq >= self.spans[i][1]:
            return
        if w.name == self.summary_topic:
            try:
                if (w.meta or {}).get("kind") == "summary":
                    return
            except CorruptionError:
                return  # unreadable: not held (`info` names it as damage)
        self.held[self.spans[i][2]] += w.count


def summary_totals(store) -> dict:
    """Totals of the smart-logging summary stream: what the robot did while nothing was stored."""
    from ..windowcount import SUMMARY_TOPIC

    total = {"minutes": 0, "messages": 0, "distance_m": 0.0, "moving_s": 0.0, "anomalies": 0,
             "peak_speed": 0.0, "peak_accel": 0.0}  # fmt: skip
    for w in store.query(SUMMARY_TOPIC, skip_damaged=True):  # damage is reported beside the totals
        for _, text in w.messages():
            rec = json.loads(text)
            total["minutes"] += 1
            for key in ("messages", "distance_m", "moving_s", "anomalies"):
                total[key] += rec.get(key, 0)
            for key in ("peak_speed", "peak_accel"):
                total[key] = max(total[key], rec.get(key, 0.0))
    return total


STATUS = {"done": "done", "interrupted": "interrupted", "error": "error",
          "unfinished": "interrupted: no end record (killed, power lost, disk full, or still recording)"}  # fmt: skip


def _flags(options: dict) -> str:
    """A run's options as the command line gave them."""
    words = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        for v in value if isinstance(value, list) else [value]:
            words.append(flag if v is True else f"{flag} {v}")
    return " ".join(words) or "-"


def runs_table(runs: list[dict]) -> str:
    """The recording runs as a table: when, how each ended, what it kept, source and options."""
    rows = []
    for r in runs:
        status = STATUS.get(r["status"], r["status"])
        if r.get("store_failed"):  # written on reopening the store after the failure (`record`)
            status += ": ended on a store failure (disk full or failing)"
        if r.get("signal"):
            status += f" ({r['signal']})"
        took = f"{(r['end_ns'] - r['start_ns']) / 1e9:.1f} s" if r["end_ns"] is not None else "-"
        kept = f"{r['messages_kept']:,} of {r['messages_in']:,}" if "messages_kept" in r else "-"
        if r.get("dropped_since"):  # the store holds fewer now than the run kept: how many, and what dropped them
            kept += f"; {r['messages_held']:,} held now ({r['dropped_by']} dropped {r['dropped_since']:,})"
        elif r.get("retention"):  # the run's records outlive its windows (store/carry.py)
            kept += f" ({r['retention']} by retention since)"
        rows.append([r["run"], iso_ns(r["start_ns"]), took, status, kept, _run_windows(r), r["source"],
                     _flags(r["options"])])  # fmt: skip
    return table(rows, ["run", "start (UTC)", "took", "status", "messages kept", "windows", "source", "options"])


def _run_windows(r: dict) -> str:
    """A run's windows of messages kept and, apart, the recorder's own summaries, as
    `record`'s end summary says them. End records written before the summaries were
    counted apart hold no "summaries": their windows include them."""
    if "windows" not in r:
        return "-"
    return f"{r['windows']:,}" + (f" (+{r['summaries']:,} summaries)" if r.get("summaries") else "")


def run(args: argparse.Namespace) -> int:
    from ..windowcount import SUMMARY_TOPIC

    info = store_info(args.store)
    if args.json:
        print(json.dumps(info, indent=2))
        return EXIT_SKIPPED if info["damage"] or info["unreadable"] or info["cut_intact"] else 0
    rows = []
    for name, st in info["streams"].items():
        span = (st["end_ns"] - st["start_ns"]) / 1e9
        rows.append([name, st["windows"], st["messages"], iso_ns(st["start_ns"]), f"{span:.1f} s",
                     human_bytes(st["json_bytes"]), human_bytes(st["stored_bytes"]),
                     f"{100 * st['ratio']:.2f} %" if st["ratio"] else "-",
                     (st["codec"] or {}).get("id", "?"), st["msgtype"] or "-"])  # fmt: skip
    print(f"store {info['path']}  ({info['segments']} segments, {human_bytes(info['disk_bytes'])} on disk)")
    print(table(rows, ["stream", "windows", "messages", "start (UTC)", "span", "JSON", "stored", "% of JSON", "codec", "type"]))
    if info["runs"]:
        print(f"runs ({len(info['runs'])}, stream /cclog/runs):")
        print(runs_table(info["runs"]))
    if info["summary"]:
        t = info["summary"]
        print(f"summary ({SUMMARY_TOPIC}, {t['minutes']} periods): {t['distance_m'] / 1000:.3f} km driven, "
              f"{t['moving_s'] / 60:.1f} min moving, peak speed {t['peak_speed']:.2f} m/s, peak acceleration "
              f"{t['peak_accel']:.2f} m/s^2, {t['anomalies']:,} anomalous of {t['messages']:,} odometry messages")
    for name, st in info["streams"].items():
        if st["records"] != st["windows"]:
            print(f"{name}: its {st['windows']} windows are stored as {st['records']} records ({st['stored_as']})")
        if st["aged"]:  # compaction ages records, each part of a window alone
            unit = "windows" if st["records"] == st["windows"] else "records"
            print(f"aged: {st['aged']} of {st[unit]} {unit} of {name} hold texts within stated error "
                  "bounds, not byte-exact (their meta key \"aged\" says how)")
    for name, st in info["dropped"]["streams"].items():
        print(f"retention dropped {st['windows']} windows ({st['messages']} messages) of {name} from "
              f"{iso_ns(st['start_ns'])} to {iso_ns(st['end_ns'])}")
    for line in info["recovery"]:
        print(f"note: a reader would drop a torn tail: {line}")
    for line, fix in zip(info["damage"], info["damage_repair"]):  # the totals above leave these windows out
        print(f"DAMAGE (not counted above; {fix}): {line}")
    for line in info["unreadable"]:
        print(f"DAMAGE (its record counted above as a window alone; `cclog fsck` names it): {line}")
    return EXIT_SKIPPED if info["damage"] or info["unreadable"] or info["cut_intact"] else 0
