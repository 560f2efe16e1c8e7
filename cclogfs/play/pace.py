"""Play a store back: its messages in time order, each when its time comes.

`paced` sleeps so that messages come out at their recorded pace times `rate`; a sink
(JSONL on a stream, ROS 1 topics, a Foxglove server) does the rest. `stream_types` finds
each stream's message type and ROS 1 definition in the window metadata a recording wrote
(see `jsontext.rostypes`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from ..export.jsonl import merged_messages

Message = tuple[str, int, str]  # (stream, stamp_ns, JSON text)
_LONGEST_SLEEP_S = 86400.0


def store_messages(store: Any, topics: Iterable[str] | None = None, start_ns: int | None = None,
                   end_ns: int | None = None) -> Iterator[Message]:  # fmt: skip
    """The chosen streams' messages in [start_ns, end_ns], in stamp order."""
    wanted = None if topics is None else set(topics)
    name = next(iter(wanted)) if wanted is not None and len(wanted) == 1 else None
    windows = (w for w in store.query(name, start_ns=start_ns, end_ns=end_ns) if wanted is None or w.name in wanted)
    return merged_messages(windows, start_ns, end_ns)


def paced(messages: Iterable[Message], rate: float = 1.0, *, skip_gaps_s: float | None = None,
          clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> Iterator[Message]:  # fmt: skip
    """Each message once `(stamp - first stamp) / rate` seconds have passed since the first.

    `skip_gaps_s`: a stretch without messages longer than this plays as if it were this
    long (a smart-logged store is mostly gaps between windows). A stamp that goes backwards
    plays at once.
    """
    if not rate > 0:
        raise ValueError("rate must be positive")
    skip_ns = None if skip_gaps_s is None else int(skip_gaps_s * 1e9)
    start = origin = prev = None
    for m in messages:
        stamp = m[1]
        if start is None:
            start, origin = clock(), stamp
        elif skip_ns is not None and stamp - prev > skip_ns:
            origin += stamp - prev - skip_ns  # the gap beyond skip_ns is cut out
        prev = stamp
        wait = start + (stamp - origin) / 1e9 / rate - clock()
        while wait > _LONGEST_SLEEP_S:  # time.sleep overflows past ~1e9 s (a tiny --rate)
            sleep(_LONGEST_SLEEP_S)
            wait -= _LONGEST_SLEEP_S
        if wait > 0:
            sleep(wait)
        yield m


def stream_types(store: Any, names: Iterable[str]) -> dict[str, dict[str, Any]]:
    """Stream -> {"msgtype", and when a recording kept them: "msgdef", "md5sum", "latching"}
    from window metadata: the first window of each stream that carries a definition, else
    any window's "msgtype". Streams with no type at all are left out."""
    out: dict[str, dict[str, Any]] = {}
    for name in names:
        found: dict[str, Any] = {}
        for w in store.query(name):
            meta = w.meta
            if "msgtype" in meta and "msgtype" not in found:
                found["msgtype"] = meta["msgtype"]
            if "msgdef" in meta and meta.get("msgtype") == found.get("msgtype"):
                found.update({k: meta[k] for k in ("msgdef", "md5sum", "latching") if k in meta})
                break
        if found:
            out[name] = found
    return out
