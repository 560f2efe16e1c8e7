"""Where a slow feature's evidence starts (issue 15, seventh pass).

The long features (turn in place over 8 s, yaw reversals over 4 s, direction reversals
over 8 s) count what happened over their window, and are gated on the present: they are
nonzero only while it still happens. A logging window opened (or grown back) for one of
them used to reach back the feature's whole span, 8 s, though a single reversal's
evidence is a second old. Now it reaches back to where the column's current evidence
starts: the first run of nonzero values of that column with a message inside the span
(a count that rises from 0 at the first flip it counts is nonzero from that flip on),
plus `margin_ns` for the despike's lag (the gates and flips use the twist despiked, which
follows a change up to two despike steps late), and never more than the span.

`evidence_back` computes it for a whole run (numpy), `EvidenceTracker` message by message
(live); they give the same numbers (tests/classifier/test_evidence.py). Stamps are the
running maximum of the header stamps, as the features take a message whose stamp does not
advance as a repeat of the previous one.
"""

from __future__ import annotations

from collections import deque

import numpy as np


def evidence_back(t: np.ndarray, V: np.ndarray, valid: np.ndarray, spans_ns, margin_ns: int) -> np.ndarray:
    """Per message (rows of V, the tracked columns) and column: how far back (ns) the
    column's evidence reaches; 0 where the column is 0 over its whole span."""
    n, k = len(t), len(spans_ns)
    out = np.zeros((n, k), dtype=np.int64)
    at = np.nonzero(valid)[0]
    m = len(at)
    if not m:
        return out
    tv = np.maximum.accumulate(np.asarray(t, dtype=np.int64))[at]
    rows = np.arange(m)
    for c, span in enumerate(spans_ns):
        nz = np.nan_to_num(V[at, c]) > 0
        begins = nz & ~np.concatenate(([False], nz[:-1]))
        first = np.maximum.accumulate(np.where(begins, rows, 0))  # a run's first row, for its rows
        nxt = np.minimum.accumulate(np.where(nz, rows, m)[::-1])[::-1]  # next nonzero row
        k0 = nxt[np.searchsorted(tv, tv - int(span), side="left")]
        found = k0 <= rows
        start = tv[first[np.minimum(k0, m - 1)]]
        out[at, c] = np.where(found, np.minimum(int(span), tv - start + margin_ns), 0)
    return out


class EvidenceTracker:
    """`evidence_back` one message at a time: `push(stamp, vector)` of a valid vector
    returns the backs of its columns `cols` (None when all are 0); `stamp(t)` for a
    message without a valid vector (it still advances the clock)."""

    def __init__(self, cols, spans_ns, margin_ns: int):
        self.cols = tuple(cols)
        self.spans = tuple(int(s) for s in spans_ns)
        self.margin = int(margin_ns)
        self.runs = tuple(deque() for _ in self.spans)  # [start, last] of nonzero runs in the span
        self.open = [False] * len(self.spans)
        self.t: int | None = None

    def stamp(self, stamp_ns: int) -> int:
        if self.t is None or stamp_ns > self.t:
            self.t = stamp_ns
        return self.t

    def push(self, stamp_ns: int, vector) -> tuple[int, ...] | None:
        t = self.stamp(stamp_ns)
        backs = None
        for c, (col, span) in enumerate(zip(self.cols, self.spans)):
            q = self.runs[c]
            if vector[col] > 0:
                if self.open[c]:
                    q[-1][1] = t
                else:
                    q.append([t, t])
                    self.open[c] = True
            else:
                self.open[c] = False
            while q and q[0][1] < t - span:
                q.popleft()
            if q:
                if backs is None:
                    backs = [0] * len(self.spans)
                backs[c] = min(span, t - q[0][0] + self.margin)
        return None if backs is None else tuple(backs)
