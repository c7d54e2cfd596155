"""The house's import rule: data flows one way (scene folder -> pose -> fit -> view ->
verify -> report), so the packages import downwards only (verify, inverse, scenes), each
room (a package's own modules, or one subpackage) imports only the rooms its
``__init__`` docstring allows ("May import: ..."), and no modules import one another in a
loop (a loop is a room that does two jobs)."""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("scenes", "inverse", "verify")      # from the ground floor up
EVERY_ROOM = "every room of totems"


def project_modules() -> dict[str, Path]:
    """Every module of the three packages, dotted name -> path (a package by its
    ``__init__.py``)."""
    found = {}
    for pkg in PACKAGES:
        for p in (ROOT / pkg).rglob("*.py"):
            parts = p.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return found


def room_of(module: str, modules: dict[str, Path]) -> str:
    """The room a module stands in: the package whose own module it is."""
    path = modules[module]
    return module if path.name == "__init__.py" else module.rsplit(".", 1)[0]


def imported(path: Path, modules) -> set[str]:
    """Project modules that ``path`` imports anywhere (top level, in functions, under
    TYPE_CHECKING): for ``from a import b`` the module ``a.b`` where it is one, else
    ``a``."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules
                     else node.module for a in node.names]
        else:
            continue
        found |= {n for n in names if n in modules}
    return found


def allowed(docstring: str) -> set[str] | None:
    """The rooms a package's docstring lets its modules import ("May import: a, b.c.");
    None for every room."""
    m = re.search(r"^May import: (.*?)(?:\n\n|\n?\Z)", docstring, re.M | re.S)
    if m is None:
        raise ValueError("no 'May import:' paragraph")
    text = " ".join(m.group(1).split())
    if EVERY_ROOM in text:
        return None
    if text.startswith("nothing else of totems"):
        return set()
    head = text.split(";")[0].rstrip(".")
    return {re.sub(r"\s*\(.*\)", "", w).strip() for w in head.split(",") if w.strip()}


def rule_breaks(modules: dict[str, Path]) -> list[str]:
    """Each import that the rule forbids, as 'module -> module (room -> room)'."""
    rules = {}
    for name, path in modules.items():
        if path.name == "__init__.py":
            rules[name] = allowed(ast.get_docstring(ast.parse(path.read_text())) or "")
    floor = {pkg: i for i, pkg in enumerate(PACKAGES)}
    breaks = []
    for name, path in sorted(modules.items()):
        room = room_of(name, modules)
        for target in sorted(imported(path, modules)):
            there = room_of(target, modules)
            if there == room or (path.name == "__init__.py" and there.startswith(name)):
                continue
            up = floor[there.split(".")[0]] > floor[room.split(".")[0]]
            ok = rules[room] is None or there in rules[room]
            if up or not ok:
                breaks.append(f"{name} -> {target} ({room} -> {there})")
    return breaks


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
    modules = {m: p for m, p in project_modules().items() if p.name != "__init__.py"}
    graph = {m: imported(p, modules) - {m} for m, p in modules.items()}
    assert import_loops(graph) == []


def test_reads_what_a_docstring_allows():
    assert allowed("Rooms.\n\nMay import: scenes, scenes.channel.\n") == {"scenes",
                                                                          "scenes.channel"}
    assert allowed("x\n\nMay import: inverse (the core), scenes; each says its own.") == \
        {"inverse", "scenes"}
    assert allowed("x\n\nMay import: verify.report,\nscenes.synthetic.\n") == \
        {"verify.report", "scenes.synthetic"}
    assert allowed("x\n\nMay import: nothing else of totems (the core).") == set()
    assert allowed("x\n\nMay import: every room of totems (it is the top).") is None
    with pytest.raises(ValueError):
        allowed("a docstring that says nothing of imports")


def test_finds_an_import_the_rule_forbids(tmp_path, monkeypatch):
    """A tiny house: scenes.photo may import scenes; an import of scenes.synthetic from it,
    and one of inverse from scenes, are both caught."""
    files = {"scenes/__init__.py": '"""c\n\nMay import: nothing else of totems."""',
             "scenes/folder.py": "import inverse.grid\n",
             "scenes/photo/__init__.py": '"""p\n\nMay import: scenes."""',
             "scenes/photo/ingest.py": "from scenes import folder\n"
                                       "from scenes.synthetic import render\n",
             "scenes/synthetic/__init__.py": '"""s\n\nMay import: scenes."""',
             "scenes/synthetic/render.py": "from scenes import folder\n",
             "inverse/__init__.py": '"""i\n\nMay import: scenes."""',
             "inverse/grid.py": "from scenes import folder\n",
             "verify/__init__.py": '"""v\n\nMay import: inverse, scenes."""'}
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert rule_breaks(project_modules()) == [
        "scenes.folder -> inverse.grid (scenes -> inverse)",
        "scenes.photo.ingest -> scenes.synthetic.render (scenes.photo -> scenes.synthetic)"]


def test_every_room_says_what_it_may_import():
    rooms = [p for p in project_modules().values() if p.name == "__init__.py"]
    assert len(rooms) >= len(PACKAGES)
    for path in rooms:
        allowed(ast.get_docstring(ast.parse(path.read_text())) or "")    # raises if silent


def test_the_package_imports_downwards_and_as_its_rooms_allow():
    assert rule_breaks(project_modules()) == []
