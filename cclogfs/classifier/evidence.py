"""Where a slow feature's evidence starts (issue 15, seventh pass).

The long features (turn in place over 8 s, yaw reversals over 4 s, direction reversals
over 8 s) count what happened over their window, and are gated on the present: they are
nonzero only while it still happens. A logging window opened (or grown back) for one of
them used to reach back the feature's whole span, 8 s, though a single reversal's
evidence is a second old. Now it reaches back to where the column's current evidence
starts: the first run of nonzero values of that column with a message inside the span
(a count that rises from 0 at the first flip it counts is nonzero from that flip on),
plus `margin_ns` (`DefaultFeatures.evidence_margin_ns`: the lead-in that the gated counts do
not see, such as the slowing into a spin, and the despike's lag), never more than the span.
`Detector.lookback_ns` then takes the earliest of the long columns.

`evidence_back` computes it for a whole run; `EvidenceHistory` for a live run, from the
stamps where each column's runs of nonzero values begin and end, answering only for the
vectors that need it (flagged ones): a message whose long columns are 0 costs a list
append and a tuple compare (tests/classifier/test_evidence.py holds the two to the same
numbers). Stamps are the running maximum of the valid vectors' header stamps, as the
features take a message whose stamp does not advance as a repeat of the previous one.
"""

from __future__ import annotations

from collections import deque
from operator import gt, itemgetter

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
    (`append(stamp, vector)`: the stamp, and per tracked column only where a run of nonzero
    values begins or ends); `take(n, flagged)` then answers for the oldest `n` not yet
    taken, at the positions `flagged` among them (from the runs: the first one ending within
    the span), and drops what no later answer needs. The same numbers as `evidence_back`,
    whatever came after the rows asked for (tests/classifier/test_evidence.py)."""

    def __init__(self, cols, spans_ns, margin_ns: int):
        self.spans = tuple(int(s) for s in spans_ns)
        self.longest = max(self.spans)
        self.margin = int(margin_ns)
        self._values = itemgetter(*cols) if len(cols) > 1 else lambda v, c=cols[0]: (v[c],)
        self._zeros = (0.0,) * len(self.spans)
        self.open = (False,) * len(self.spans)  # whether each column is nonzero now
        self.any_open = False
        # Per column: [start stamp, last stamp (None while open), row it starts at]; the row
        # tells runs apart from a later one whose stamp did not advance.
        self.runs = tuple(deque() for _ in self.spans)
        self.stamps: list[int] = []  # of the rows not yet taken (running maximum)
        self.base = 0  # row number of stamps[0]
        self.taken = 0
        self.newest = -(1 << 63)  # the running maximum stamp

    def append(self, stamp_ns: int, vector) -> None:
        newest = self.newest
        if stamp_ns < newest:
            stamp_ns = newest
        self.stamps.append(stamp_ns)
        values = self._values(vector)
        if values == self._zeros and not self.any_open:  # most messages: nothing counted
            self.newest = stamp_ns
            return
        now = tuple(map(gt, values, self._zeros))  # NaN: False, as 0
        if now != self.open:
            row = self.base + len(self.stamps) - 1
            for runs, was, is_on in zip(self.runs, self.open, now):
                if is_on and not was:
                    runs.append([stamp_ns, None, row])
                elif was and not is_on:
                    runs[-1][1] = newest
            self.open = now
            self.any_open = any(now)
        self.newest = stamp_ns

    def take(self, n: int, flagged=()) -> np.ndarray:
        """The backs of rows `flagged` (ascending positions among the next `n` rows)."""
        first = self.taken
        self.taken += n
        out = _NONE
        if len(flagged):
            rows = [first + int(r) for r in flagged]
            out = np.array([[self._back(k, self.stamps[i], self.base + i) for k in range(len(self.spans))]
                            for i in rows], dtype=np.int64)  # fmt: skip
        if self.taken >= 256:
            self._trim()
        return out

    def _back(self, k: int, t: int, row: int) -> int:
        span = self.spans[k]
        for start, last, begins in self.runs[k]:
            if begins > row:
                break
            if last is None or last >= t - span:
                return min(span, t - start + self.margin)
        return 0

    def _trim(self) -> None:
        """Drop the taken stamps, and the runs that ended before any later answer's span."""
        edge = self.stamps[self.taken - 1] - self.longest
        del self.stamps[: self.taken]
        self.base += self.taken
        self.taken = 0
        for runs in self.runs:
            while runs and runs[0][1] is not None and runs[0][1] < edge:
                runs.popleft()
