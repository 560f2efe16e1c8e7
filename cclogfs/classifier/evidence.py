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

`evidence_back` computes it for a whole run; `EvidenceHistory` keeps the recent vectors
of a live run and computes it, by the same function, only for the vectors that need it
(flagged ones), so that a message costs two list appends (tests/classifier/test_evidence.py
holds the two to the same numbers). Stamps are the running maximum of the valid vectors'
header stamps, as the features take a message whose stamp does not advance as a repeat of
the previous one.
"""

from __future__ import annotations

from bisect import bisect_left

import numpy as np


def evidence_back(t: np.ndarray, V: np.ndarray, valid: np.ndarray, spans_ns, margin_ns: int) -> np.ndarray:
    """Per message (rows of V, the tracked columns) and column: how far back (ns) the
    column's evidence reaches; 0 where the column is 0 over its whole span. A row's answer
    depends on that row and the rows before it only."""
    n, k = len(t), len(spans_ns)
    out = np.zeros((n, k), dtype=np.int64)
    at = np.nonzero(valid)[0]
    m = len(at)
    if not m:
        return out
    tv = np.maximum.accumulate(np.asarray(t, dtype=np.int64)[at])
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


_NONE = np.zeros((0, 0), dtype=np.int64)  # `take`'s answer for no row


class EvidenceHistory:
    """`evidence_back` over a live run. The valid vectors are appended as they come
    (`append(stamp, vector)`: the running maximum stamp and the vector, two list appends);
    `take(n, flagged)` then answers for the oldest `n` not yet taken, at the positions
    `flagged` among them, and drops what no later answer needs."""

    def __init__(self, cols, spans_ns, margin_ns: int):
        self.cols = list(cols)
        self.spans = np.asarray(spans_ns, dtype=np.int64)
        self.longest = int(self.spans.max())
        self.margin = int(margin_ns)
        self.stamps: list[int] = []  # running maximum, so sorted
        self.vectors: list = []
        self.taken = 0  # rows answered for (or passed) so far, from the lists' start
        self.newest = None

    def append(self, stamp_ns: int, vector) -> None:
        if self.newest is not None and stamp_ns < self.newest:
            stamp_ns = self.newest
        self.newest = stamp_ns
        self.stamps.append(stamp_ns)
        self.vectors.append(vector)

    def take(self, n: int, flagged=()) -> np.ndarray:
        """The backs of rows `flagged` (ascending positions among the next `n` rows)."""
        first = self.taken
        self.taken += n
        if not len(flagged):  # most messages: nothing to compute
            if self.taken >= 1024:
                self._trim()
            return _NONE
        rows = first + np.asarray(flagged, dtype=np.int64)
        # From the last row older than the first asked's longest span: a run through
        # it reaches back the whole span whatever came before (the answer is the same).
        lo = max(bisect_left(self.stamps, self.stamps[rows[0]] - self.longest, 0, int(rows[0])) - 1, 0)
        end = int(rows[-1]) + 1
        V = np.array([[v[c] for c in self.cols] for v in self.vectors[lo:end]], dtype=np.float64)
        t = np.array(self.stamps[lo:end], dtype=np.int64)
        out = evidence_back(t, V, np.ones(end - lo, dtype=bool), self.spans, self.margin)[rows - lo]
        self._trim()
        return out

    def _trim(self) -> None:
        """Drop rows no later answer reads (by `take`'s rule), a few hundred at a time."""
        if self.taken < 512 or self.taken > len(self.stamps):
            return
        cut = bisect_left(self.stamps, self.stamps[self.taken - 1] - self.longest, 0, self.taken) - 1
        if cut >= 256:
            del self.stamps[:cut]
            del self.vectors[:cut]
            self.taken -= cut
