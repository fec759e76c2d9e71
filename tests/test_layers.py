"""The architecture, enforced: the import contracts of pyproject.toml ([tool.importlinter])
hold, and no two modules or packages of simbench import each other, even lazily."""

from __future__ import annotations

import collections
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold():
    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    assert {c["type"] for c in contracts} >= {"layers", "forbidden"}
    lint = Path(sys.executable).with_name("lint-imports")
    out = subprocess.run([str(lint)], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert f"Contracts: {len(contracts)} kept, 0 broken." in out.stdout


def _unit(module: str) -> str:
    """A module's top-level unit: simbench.X for a module or package X."""
    return ".".join(module.split(".")[:2])


def test_no_import_cycles_between_modules():
    """Between simbench's top-level modules and packages (a package's own modules importing its
    __init__ is Python's normal package set-up, not a cycle), counting imports inside functions
    too: a cycle through a lazy import is still a knot."""
    import grimp

    graph = grimp.build_graph("simbench", exclude_type_checking_imports=True)
    edges = collections.defaultdict(set)
    for m in graph.modules:
        for t in graph.find_modules_directly_imported_by(m):
            a, b = _unit(m), _unit(t)
            if a != b and "simbench" not in (a, b):
                edges[a].add(b)
    cycles = _cycles(edges)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(u: str, path: list[str]) -> None:
        state[u] = 1
        for v in sorted(edges.get(u, ())):
            if state.get(v) == 1:
                cycles.append(path[path.index(v) :] + [v])
            elif v not in state:
                visit(v, path + [v])
        state[u] = 2

    for u in sorted(edges):
        if u not in state:
            visit(u, [u])
    return cycles


def test_no_import_cycles_inside_the_packages():
    """Between the modules of one package (simbench.sim.capture and simbench.sim.drive, say),
    lazy imports included; a package's __init__ is left out (its modules importing it, or it
    re-exporting them, is the normal package set-up)."""
    import grimp

    graph = grimp.build_graph("simbench", exclude_type_checking_imports=True)
    packages = {m for m in graph.modules if graph.find_children(m)}
    edges: dict[str, set[str]] = collections.defaultdict(set)
    for m in graph.modules:
        for t in graph.find_modules_directly_imported_by(m):
            if m in packages or t in packages or m.rsplit(".", 1)[0] != t.rsplit(".", 1)[0]:
                continue
            edges[m].add(t)
    cycles = _cycles(edges)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_the_command_line_names_no_system():
    """simbench/cli holds no domain logic: no registered system's name appears in its code (it
    asks the systems registry; the default system is simbench.systems.DEFAULT_SYSTEM)."""
    import ast
    import re

    from simbench.systems import system_names

    names = re.compile(r"\b(" + "|".join(map(re.escape, system_names())) + r")\b")
    found = []
    for path in sorted((ROOT / "simbench" / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and names.search(node.value):
                found.append(f"{path.name}:{node.lineno}: {node.value[:60]!r}")
            elif isinstance(node, ast.Name | ast.Attribute) and names.search(
                getattr(node, "id", getattr(node, "attr", ""))
            ):
                found.append(f"{path.name}:{node.lineno}")
    assert not found, "system names in simbench/cli: " + "; ".join(found)
