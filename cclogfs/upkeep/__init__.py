"""Upkeep of a store: old windows aged to lower fidelity within stated error bounds, the
oldest segments dropped to fit a storage budget.

- `policy`: what aging does to a window's JSON texts (no storage here);
- `job`: `compact` (and `preview`, its dry run) applies a policy and a budget to a store;
- `background`: `Upkeep`, the same while recording, in a background thread.

docs/UPKEEP.md describes the commands and the guarantees.
"""

from .background import Upkeep
from .job import DEFAULT_EXCLUDE, CompactReport, compact, passes_of, preview, unmatched_rules
from .policy import Policy, Rule, grid_step, parse_rule

__all__ = ["DEFAULT_EXCLUDE", "CompactReport", "Policy", "Rule", "Upkeep", "compact", "grid_step", "parse_rule", "unmatched_rules",
           "passes_of", "preview"]  # fmt: skip
