"""The faces' layout (cli/, viz/, _io/): no import cycle, no private name across modules.

Read from the source with :mod:`ast` (every import, function-local ones included), so
that a cycle closed through a function-local import is found too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "manip_id"
FACES = ("cli", "viz", "_io")


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    out = {}
    for face in FACES:
        for path in sorted((PACKAGE / face).rglob("*.py")):
            out[_module_name(path)] = path
    return out


def _imports(name: str, path: Path):
    """``(target module, imported names)`` of every import in the module, resolved."""
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            yield target, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, []


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for name, path in mods.items():
        for target, names in _imports(name, path):
            for n in names:  # "from . import _files" imports a module
                if f"{target}.{n}" in mods:
                    graph[name].add(f"{target}.{n}")
            if target in mods and target != name:
                graph[name].add(target)
    return graph


def test_no_import_cycle_among_the_faces():
    graph = _graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        for nxt in sorted(graph[node]):
            if nxt.rpartition(".")[0] == node or node.startswith(nxt + "."):
                continue  # a package and its own members (re-exports in __init__)
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt) :] + [nxt] if nxt in stack else [node, nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert cycles == []


def test_no_private_name_imported_across_modules():
    private = []
    for name, path in _modules().items():
        for target, names in _imports(name, path):
            if not target.startswith("manip_id"):
                continue
            for n in names:
                if n.startswith("_") and n != "__name__" and f"{target}.{n}" not in _modules():
                    private.append(f"{name}: from {target} import {n}")
    assert private == []


@pytest.mark.parametrize("name", sorted(_modules()))
def test_module_size(name):
    lines = len(_modules()[name].read_text().splitlines())
    assert lines < 600, f"{name}: {lines} lines"
