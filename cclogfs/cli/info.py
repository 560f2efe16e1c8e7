"""`cclog info STORE`: what a store holds."""

from __future__ import annotations

import argparse
import json

from ..store import open_store
from ._fmt import human_bytes, iso_ns, table

EXAMPLES = """examples:
  cclog info out/demo/store
  cclog info out/demo/store --json | jq '.streams["/odom"].messages'
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="streams, windows, messages, time span and sizes of a store",
                       description="Show what a store holds: per stream the windows, messages, time span, "
                                   "stored bytes, codec and the ratio against the messages' JSON.",
                       epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("store", help="store directory")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=run)


def store_info(path: str) -> dict:
    """Everything `cclog info` prints, as a dict."""
    with open_store(path, readonly=True) as store:
        streams = store.streams()
        for name, st in streams.items():
            last = None
            for last in store.query(name, start_ns=st["end_ns"], end_ns=st["end_ns"]):
                pass
            st["codec"] = last.codec_config if last is not None else None
            st["ratio"] = st["stored_bytes"] / st["json_bytes"] if st["json_bytes"] else None
        return {
            "path": path,
            "store_id": store.manifest["store_id"],
            "segments": len(store.sealed) + len(store.unsealed),
            "disk_bytes": store.disk_bytes(),
            "json_bytes": sum(s["json_bytes"] for s in streams.values()),
            "streams": streams,
            "recovery": [str(p) for p in store.recovery.problems],
        }


def run(args: argparse.Namespace) -> int:
    info = store_info(args.store)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    rows = []
    for name, st in info["streams"].items():
        span = (st["end_ns"] - st["start_ns"]) / 1e9
        rows.append([name, st["windows"], st["messages"], iso_ns(st["start_ns"]), f"{span:.1f} s",
                     human_bytes(st["json_bytes"]), human_bytes(st["stored_bytes"]),
                     f"{100 * st['ratio']:.2f} %" if st["ratio"] else "-",
                     (st["codec"] or {}).get("id", "?")])  # fmt: skip
    print(f"store {info['path']}  ({info['segments']} segments, {human_bytes(info['disk_bytes'])} on disk)")
    print(table(rows, ["stream", "windows", "messages", "start (UTC)", "span", "JSON", "stored", "% of JSON", "codec"]))
    for line in info["recovery"]:
        print(f"note: a reader would drop a torn tail: {line}")
    return 0
