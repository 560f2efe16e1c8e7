"""Detection quality: the paper's per-message Table 1 and per-event figures for windows."""

from __future__ import annotations

from typing import Iterable

import numpy as np

from ..windowcount import WindowJoiner, link_of
from .api import parse_labels
from .windows import PendingWindow

__all__ = ["detection_delays", "event_table", "format_event_table", "format_message_table", "message_table",
           "window_spans"]  # fmt: skip


def _inside(stamp_ns: np.ndarray, spans: Iterable[tuple[int, int]]) -> np.ndarray:
    """Mask of stamps inside any closed span [start, end]."""
    mask = np.zeros(len(stamp_ns), dtype=bool)
    for a, b in spans:
        mask[np.searchsorted(stamp_ns, a, "left") : np.searchsorted(stamp_ns, b, "right")] = True
    return mask


def _ratio(a: float, b: float) -> float:
    return float(a / b) if b else float("nan")


def message_table(stamp_ns: np.ndarray, flags: np.ndarray, labels) -> dict:
    """Table 1 of the paper: a message is anomalous when inside a labelled event."""
    truth = _inside(np.asarray(stamp_ns), [(e["start_ns"], e["end_ns"]) for e in parse_labels(labels)])
    flags = np.asarray(flags, dtype=bool)
    tp, fp = int(np.sum(flags & truth)), int(np.sum(flags & ~truth))
    fn, tn = int(np.sum(~flags & truth)), int(np.sum(~flags & ~truth))
    return {"total": len(flags), "tp": tp, "fp": fp, "fn": fn, "tn": tn,
            "precision": _ratio(tp, tp + fp), "recall": _ratio(tp, tp + fn)}  # fmt: skip


def window_spans(windows: Iterable[PendingWindow], topic: str = "/odom") -> list[tuple[int, int]]:
    """(start_ns, end_ns) of each stored window of `topic`, its parts joined as `cclog
    record` and `cclog info` count them (`windowcount`: by window_id and part)."""
    spans: dict[int, list[int]] = {}
    joiner = WindowJoiner()
    for w in windows:
        key = joiner.join(w.topic, link_of(w.meta))[0]
        if w.topic != topic or not w.messages:
            continue
        s = spans.setdefault(key, [w.start_ns, w.end_ns])
        s[0], s[1] = min(s[0], w.start_ns), max(s[1], w.end_ns)
    return sorted((a, b) for a, b in spans.values())


def detection_delays(stamp_ns: np.ndarray, flags: np.ndarray, labels,
                     horizon_ns: int = 2 * 10**9) -> list[float]:
    """Per event, seconds from its start to the first anomalous message at or after it,
    up to `horizon_ns` after its end (a later flag is not this event's); NaN where none."""
    stamp_ns, flags = np.asarray(stamp_ns), np.asarray(flags, dtype=bool)
    out = []
    for e in parse_labels(labels):
        a = np.searchsorted(stamp_ns, e["start_ns"], "left")
        b = np.searchsorted(stamp_ns, e["end_ns"] + horizon_ns, "right")
        hit = np.nonzero(flags[a:b])[0]
        out.append((int(stamp_ns[a + hit[0]]) - e["start_ns"]) / 1e9 if len(hit) else float("nan"))
    return out


def event_table(stamp_ns: np.ndarray, spans: list[tuple[int, int]], labels,
                flags: np.ndarray | None = None) -> dict:  # fmt: skip
    """Per-event figures: an event is recalled when every message in it was kept; a false
    window touches no event; false windows per 10 minutes of nominal time (run time less
    the events); with `flags`, detection delays (median and max over detected events; None without)."""
    stamp_ns = np.asarray(stamp_ns)
    events = parse_labels(labels)
    kept = _inside(stamp_ns, spans)
    recalled = 0
    for e in events:
        sel = _inside(stamp_ns, [(e["start_ns"], e["end_ns"])])
        recalled += bool(sel.any() and kept[sel].all())
    false = sum(
        1 for a, b in spans if not any(a <= e["end_ns"] and e["start_ns"] <= b for e in events)
    )
    minutes = (stamp_ns[-1] - stamp_ns[0]) / 60e9 if len(stamp_ns) > 1 else 0.0
    nominal = minutes - sum(e["end_ns"] - e["start_ns"] for e in events) / 60e9
    delays = [d for d in detection_delays(stamp_ns, flags, events) if d == d] if flags is not None else []
    return {
        "events": len(events), "recalled": recalled, "event_recall": _ratio(recalled, len(events)),
        "windows": len(spans), "false_windows": false,
        "window_precision": _ratio(len(spans) - false, len(spans)),
        "false_per_10min": _ratio(false * 10, nominal), "minutes": minutes,
        "nominal_minutes": nominal,
        "kept_fraction": _ratio(int(kept.sum()), len(stamp_ns)),
        "detected": len(delays),
        "delay_median_s": float(np.median(delays)) if delays else None,
        "delay_max_s": float(np.max(delays)) if delays else None,
    }  # fmt: skip


def _fmt(v) -> str:
    if isinstance(v, float) and v != v:  # 0 of 0: nothing flagged (or no event to recall)
        return "n/a"
    return f"{100 * v:.1f}%" if isinstance(v, float) and v <= 1 else str(v)


def format_message_table(t: dict) -> str:
    """The per-message table laid out like the paper's Table 1."""
    rows = [("Total Events", t["total"]), ("True Positives", t["tp"]),
            ("False Positives", t["fp"]), ("False Negatives", t["fn"]),
            ("True Negatives", t["tn"]), ("Precision", _fmt(t["precision"])),
            ("Recall", _fmt(t["recall"]))]  # fmt: skip
    return "\n".join(f"{k:<16} {v:>8}" for k, v in rows)


def format_event_table(t: dict) -> str:
    """Per-event figures, one per line."""
    rows = [("Events", t["events"]), ("Events recalled", f"{t['recalled']} ({_fmt(t['event_recall'])})"),
            ("Windows stored", t["windows"]), ("False windows", t["false_windows"]),
            ("Window precision", _fmt(t["window_precision"])),
            ("False / 10 min", f"{t['false_per_10min']:.2f} (of {t['nominal_minutes']:.1f} min nominal)"),
            ("Messages kept", _fmt(t["kept_fraction"]))]  # fmt: skip
    if t.get("detected"):
        rows.append(("Detection delay", f"median {t['delay_median_s']:.2f} s, max {t['delay_max_s']:.2f} s"))
    return "\n".join(f"{k:<17} {v:>12}" for k, v in rows)
