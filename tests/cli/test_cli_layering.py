"""The CLI's modules stay apart: a subcommand imports `cli.common`, never another
subcommand (else `cclog eval` would break when `train` changes, and the two could cycle)."""

from __future__ import annotations

import ast
from pathlib import Path

from cclogfs.cli import COMMANDS

CLI = Path(__file__).resolve().parents[2] / "cclogfs" / "cli"


def _sibling_imports(path: Path) -> set[str]:
    """Modules of the cli package that `path` imports, at any depth (lazy imports too)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                out.add(node.module.split(".")[0])
            else:  # from . import x
                out.update(alias.name for alias in node.names)
    return out


def test_every_command_has_a_module():
    assert {p.stem for p in CLI.glob("*.py")} >= set(COMMANDS)


def test_no_subcommand_imports_another():
    offenders = {name: sorted(_sibling_imports(CLI / f"{name}.py") & set(COMMANDS)) for name in COMMANDS}
    assert {name: found for name, found in offenders.items() if found} == {}


def test_common_imports_no_subcommand():
    assert not _sibling_imports(CLI / "common.py") & set(COMMANDS)
