"""The package's modules import one another without loops: data flows one way (scene
folder -> pose -> fit -> verify -> report), and a loop is a room that does two jobs."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("scenes", "inverse", "verify")


def project_modules() -> dict[str, Path]:
    return {f"{pkg}.{p.stem}": p for pkg in PACKAGES for p in (ROOT / pkg).glob("*.py")
            if p.stem != "__init__"}


def imported(path: Path, modules) -> set[str]:
    """Project modules that ``path`` imports anywhere (top level, in functions, under
    TYPE_CHECKING)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found |= {f"{node.module}.{a.name}" for a in node.names}
    return found & set(modules)


def import_loops(graph: dict[str, set[str]]) -> list[list[str]]:
    """Groups of modules that reach one another by imports (strong components > 1)."""
    names = sorted(graph)
    index = {n: i for i, n in enumerate(names)}
    rows = [index[a] for a in names for b in graph[a]]
    cols = [index[b] for a in names for b in graph[a]]
    adj = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(names),) * 2)
    n, labels = connected_components(adj, directed=True, connection="strong")
    groups = [[names[i] for i in np.flatnonzero(labels == k)] for k in range(n)]
    return [g for g in groups if len(g) > 1]


def test_finds_a_loop_when_there_is_one():
    assert import_loops({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_loops({"a": {"b"}, "b": set()}) == []


def test_the_package_has_no_import_loops():
    modules = project_modules()
    graph = {m: imported(p, modules) - {m} for m, p in modules.items()}
    assert import_loops(graph) == []
