"""The package's layering, derived from its files (ast, nothing imported), so it cannot
drift: a new module is checked the day it is added.

- the storage engine (cclogfs/store) imports only the codecs, the errors, the JSON text
  checks and the signal guard: nothing of the classifier, ingest, export, upkeep, the
  pipeline, the CLI, the demo or the simulator;
- the classifier imports only the errors, the JSON text conventions and how windows are
  counted from their metadata (`windowcount`, which imports nothing; and the package
  version): nothing of storage, codecs, ingest, export, upkeep, pipeline or CLI;
Both are allow-lists, so a package added later is outside them until someone decides otherwise.
- no import cycle anywhere in cclogfs (module level, as `python3 ../shared/tools/imports.py
  cclogfs` counts them).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "cclogfs"


def _modules() -> dict[str, Path]:
    out = {}
    # A compiled module is known by its C source (setup.py builds cclogfs/codecs/_rows.c).
    for f in [*ROOT.rglob("*.py"), *ROOT.rglob("*.c")]:
        parts = list(f.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


MODULES = _modules()


def _imports(name: str) -> set[str]:
    """Absolute names of what module `name` imports (at any depth of its code)."""
    f = MODULES[name]
    if f.suffix == ".c":
        return set()  # C code imports nothing of cclogfs
    pkg = name if f.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            found.add(prefix)
            found.update(f"{prefix}.{a.name}" for a in node.names)
    return found


def _in_package(name: str) -> str | None:
    """The cclogfs module an imported name refers to (longest known prefix), or None."""
    while name and name not in MODULES:
        name = name.rsplit(".", 1)[0] if "." in name else ""
    return name or None


def _subpackage(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


# What each guarded package may import from cclogfs besides itself ("" is the top-level
# package itself, "__version__" a name in it). An allow-list rather than a list of what is
# forbidden: a forbidden-list names packages, goes stale when they are renamed (it named
# `compact` and `aging` after they had moved) and lets through any package added later.
ALLOWED = {
    "store": {"codecs", "errors", "jsontext", "_signals"},
    "classifier": {"errors", "jsontext", "windowcount", "", "__version__"},
}


def _violations(pkg: str) -> list[str]:
    bad = []
    for module in sorted(m for m in MODULES if m == f"cclogfs.{pkg}" or m.startswith(f"cclogfs.{pkg}.")):
        for target in _imports(module):
            if target.split(".")[0] == "cclogfs" and _subpackage(target) not in ALLOWED[pkg] | {pkg}:
                bad.append(f"{module} imports {target}")
    return bad


def test_the_packages_exist():
    # Guards the derivation itself: an empty walk would pass every check below.
    for pkg in ALLOWED:
        assert sum(1 for m in MODULES if m.startswith(f"cclogfs.{pkg}.")) >= 5, pkg


def test_the_allowed_names_exist():
    # So the allow-lists cannot drift: each names a module of the package (or its version).
    import cclogfs

    for pkg, allowed in ALLOWED.items():
        for name in allowed - {""}:
            assert f"cclogfs.{name}" in MODULES or hasattr(cclogfs, name), (pkg, name)


@pytest.mark.parametrize("pkg", sorted(ALLOWED))
def test_package_imports_nothing_above_it(pkg):
    assert _violations(pkg) == []


def test_a_package_added_later_is_outside_the_allow_list(tmp_path, monkeypatch):
    # The check must be able to fail, also for a package nobody has listed yet.
    monkeypatch.setitem(MODULES, "cclogfs.zz_new", tmp_path / "zz_new.py")
    monkeypatch.setitem(MODULES, "cclogfs.store.zz_a", tmp_path / "a.py")
    monkeypatch.setitem(MODULES, "cclogfs.classifier.zz_b", tmp_path / "b.py")
    (tmp_path / "zz_new.py").write_text("")
    (tmp_path / "a.py").write_text("from ..zz_new import x\n")
    (tmp_path / "b.py").write_text("from .. import Store\n")
    assert "cclogfs.store.zz_a imports cclogfs.zz_new" in _violations("store")
    assert "cclogfs.classifier.zz_b imports cclogfs.Store" in _violations("classifier")


def _cycles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    graph = {m: {t for t in map(_in_package, _imports(m)) if t and t != m} for m in MODULES}
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph)))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    assert _cycles() == []


def test_the_cycle_check_sees_a_cycle(tmp_path, monkeypatch):
    # The check must be able to fail: two modules importing each other are one cycle.
    monkeypatch.setitem(MODULES, "cclogfs.zz_a", tmp_path / "a.py")
    monkeypatch.setitem(MODULES, "cclogfs.zz_b", tmp_path / "b.py")
    (tmp_path / "a.py").write_text("from .zz_b import y\n")
    (tmp_path / "b.py").write_text("from .zz_a import x\n")
    assert ["cclogfs.zz_a", "cclogfs.zz_b"] in _cycles()


def test_importing_the_classifier_loads_no_storage():
    # At run time too: cclogfs/__init__ exports the store lazily.
    code = ("import sys, cclogfs.classifier, cclogfs.classifier.testing;"
            "print(sorted({m.split('.')[1] for m in sys.modules if m.startswith('cclogfs.')}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = set(eval(out.stdout))  # noqa: S307 - our own printed list
    assert loaded <= ALLOWED["classifier"] | {"classifier"}, loaded
