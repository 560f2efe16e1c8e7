"""Which odometry messages the features can use, and why the others are left out.

The default features skip a message with a NaN or infinite value and one whose header
stamp does not pass every earlier usable stamp (`DefaultFeatures.batch`). Silently, that
turned a run whose stamps go backwards into "needs at least 20 finite nominal vectors,
got 0"; this module says which messages were left out and the first of each kind.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .features import NS, RAW_NAMES, OdomArrays, accepted_rows

__all__ = ["Usable", "usable"]


@dataclass
class Usable:
    """What the features can use of one run. Indexes are 0-based message numbers on the topic."""

    total: int
    usable: int
    scored: int  # usable messages with a valid feature vector (not a copy of an earlier one)
    nonfinite: int
    first_nonfinite: tuple[int, str] | None  # (index, field)
    stale: int  # finite, but the stamp does not pass every earlier usable one
    first_stale: tuple[int, int, int] | None  # (index, its stamp, the newest earlier usable stamp)
    constant: bool  # every stamp is the same
    accepted: np.ndarray = field(repr=False, default=None)  # mask of the usable messages

    @property
    def left_out(self) -> int:
        return self.nonfinite + self.stale

    def reasons(self) -> str:
        """Why messages were left out, naming the first of each kind ("" when none was)."""
        out = []
        if self.constant and self.total > 1:
            out.append(f"all {self.total:,} header stamps are equal ({_secs(self.first_stale[2])} s)")
        elif self.stale:
            i, t, before = self.first_stale
            how = "repeats" if t == before else "goes backwards"
            out.append(f"{self.stale:,} whose header stamp does not advance; the first, message {i + 1:,}, "
                       f"{how} (t={_secs(t)} s after {_secs(before)} s)")  # fmt: skip
        if self.nonfinite:
            i, field = self.first_nonfinite
            out.append(f"{self.nonfinite:,} with NaN or infinite values; the first, message {i + 1:,}, "
                       f"in {field}")  # fmt: skip
        return "; ".join(out)

    def describe(self, name: str, topic: str) -> str:
        """'NAME: U of N TOPIC messages usable: REASONS' (one line, no full stop)."""
        said = f"{name}: {self.usable:,} of {self.total:,} {topic} messages usable"
        return f"{said}: {self.reasons()}" if self.left_out else said


def usable(odom: OdomArrays, feature_set) -> Usable:
    """The messages of `odom` that `feature_set` uses. Feature sets without stamp rules
    (the paper's) leave out only non-finite messages."""
    t, raw = odom.stamp_ns, odom.raw
    finite = np.isfinite(raw).all(axis=1)
    checks_stamps = hasattr(feature_set, "horizon_ns")
    accepted = accepted_rows(t, finite) if checks_stamps else finite
    stale = finite & ~accepted
    X, valid = feature_set.batch(odom)
    first_nonfinite = first_stale = None
    if not finite.all():
        i = int(np.argmin(finite))
        first_nonfinite = (i, RAW_NAMES[int(np.argmin(np.isfinite(raw[i])))])
    if stale.any():
        i = int(np.argmax(stale))
        before = t[:i][finite[:i] & accepted[:i]]
        first_stale = (i, int(t[i]), int(before.max()))
    return Usable(total=len(t), usable=int(accepted.sum()), scored=int((accepted & valid & np.isfinite(X).all(axis=1)).sum()),
                  nonfinite=int((~finite).sum()), first_nonfinite=first_nonfinite,
                  stale=int(stale.sum()), first_stale=first_stale,
                  constant=bool(checks_stamps and len(t) > 1 and finite.all() and (t == t[0]).all()),
                  accepted=accepted)  # fmt: skip


def _secs(stamp_ns: int) -> str:
    return f"{stamp_ns // NS}.{stamp_ns % NS:09d}"
