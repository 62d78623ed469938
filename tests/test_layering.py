"""The import graph of the project's packages, read from the code itself: no module imports
one that imports it back (directly or round a loop), no subpackage depends on one that
depends on it, and no package imports one above it in ../shared/DESIGN.md's stack.

Every import counts, also those inside functions and under TYPE_CHECKING: a lazy import
is still a dependency, and hiding a circle inside a function does not remove it."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("inference", "calibration", "drivers", "sim_devices", "app")
# DESIGN.md: what each top-level package may import of ours
ALLOWED = {
    "inference": set(),
    "calibration": {"inference"},
    "drivers": set(),
    "sim_devices": {"inference", "drivers"},
    "app": {"inference", "calibration", "drivers", "sim_devices"},
}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in (REPO / pkg).rglob("*.py")}


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """The project modules ``name`` imports (``from pkg import mod`` counts as ``pkg.mod``)."""
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in known:  # `import a.b.c` of a package resolves to its deepest module of ours
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def import_graph() -> dict[str, set[str]]:
    mods = project_modules()
    known = set(mods)
    return {m: imports_of(m, p, known) for m, p in mods.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one member (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def package_of(module: str, graph: dict[str, set[str]]) -> str:
    """A module's subpackage (its parent); a package's ``__init__`` is a node of its own: a
    facade that gathers its subpackages (``drivers.open_device``) sits above them, while
    the modules beside it (``drivers.base``) sit below."""
    if any(m.startswith(module + ".") for m in graph):
        return module + ".__init__"
    return module.rpartition(".")[0] or module


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph()


def test_the_walk_sees_the_project(graph):
    # guards the walk itself: a resolver that lost imports would pass every check below
    assert len(graph) > 100
    assert "inference.model.config" in graph["inference.model.denoiser"]
    assert "inference.body.rotations" in graph["calibration.core"]
    assert "inference.loaders.bvh" in graph["inference.loaders"]  # a lazy import inside a function


def test_no_module_imports_itself_round_a_circle(graph):
    assert circles(graph) == []


def test_no_subpackage_circles(graph):
    pkg_graph: dict[str, set[str]] = {}
    for m, deps in graph.items():
        p = package_of(m, graph)
        pkg_graph.setdefault(p, set()).update(package_of(d, graph) for d in deps if package_of(d, graph) != p)
    assert circles(pkg_graph) == []


def test_no_import_points_up_the_stack(graph):
    upward = sorted(f"{m} -> {d}" for m, deps in graph.items() for d in deps
                    if d.split(".")[0] != m.split(".")[0] and d.split(".")[0] not in ALLOWED[m.split(".")[0]])
    assert upward == []


def test_circles_are_found():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert circles(g) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


MAX_LINES = 600  # docs/design.md: a module past it is split by what its parts do
SIZE_CHECKED = ("app", "drivers", "calibration")


def test_no_module_is_over_600_lines():
    long = sorted(f"{p.relative_to(REPO)}: {n}" for pkg in SIZE_CHECKED for p in (REPO / pkg).rglob("*.py")
                  if (n := len(p.read_text().splitlines())) > MAX_LINES)
    assert long == []


def test_app_root_holds_no_loose_modules():
    # docs/design.md, "The layers": every module of app/ sits in a package named for what it does
    loose = sorted(p.name for p in (REPO / "app").glob("*.py"))
    assert set(loose) <= {"__init__.py"}, loose
