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
    state: dict[str, int] = {}
    cycles = []

    def visit(u: str, path: list[str]) -> None:
        state[u] = 1
        for v in sorted(edges[u]):
            if state.get(v) == 1:
                cycles.append(path[path.index(v) :] + [v])
            elif v not in state:
                visit(v, path + [v])
        state[u] = 2

    for u in sorted(edges):
        if u not in state:
            visit(u, [u])
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)
