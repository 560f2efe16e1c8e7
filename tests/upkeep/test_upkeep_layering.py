"""Upkeep sees the store only through its public API (`sealed_segments()`,
`active_first_seq`, `rewrite`, ...): a private member it reached into could change under it
without a test of the store noticing."""

from __future__ import annotations

import ast
from pathlib import Path

UPKEEP = Path(__file__).resolve().parents[2] / "cclogfs" / "upkeep"
# The store's internal state that upkeep used to read directly.
INTERNAL = {"manifest", "sealed", "active", "unsealed"}


def _reaches_in(path: Path) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Attribute):
            continue
        own = isinstance(node.value, ast.Name) and node.value.id == "self"
        private = node.attr.startswith("_") and not node.attr.startswith("__")
        if (private and not own) or node.attr in INTERNAL:
            out.append(f"{path.name}:{node.lineno}: .{node.attr}")
    return out


def test_upkeep_uses_only_public_store_api():
    modules = sorted(UPKEEP.glob("*.py"))
    assert {p.stem for p in modules} >= {"policy", "job", "background"}
    assert [hit for p in modules for hit in _reaches_in(p)] == []


def test_policy_knows_nothing_of_storage():
    imported = set()
    for node in ast.walk(ast.parse((UPKEEP / "policy.py").read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            imported.add(node.module or "")
    assert imported <= {"errors"}, imported
