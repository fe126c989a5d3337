"""The package's shape, read from its source with ``ast`` (no import of manip_id).

The rules (DESIGN.md, issue 22):

- no import cycle between manip_id modules, counting module-level AND function-local
  imports (imports under ``if TYPE_CHECKING:`` never run and are not counted);
- a function-local import only of an optional heavy library (:data:`HEAVY`);
- no private name of another manip_id module: neither ``from .x import _y`` nor
  ``x._y`` on an imported manip_id module;
- modules of at most 600 lines, functions of at most 80 lines of code (its docstring
  not counted: the numpydoc sections are wanted; a function that declares an argparse
  parser, i.e. calls ``add_argument``, is excepted: a list of declarations reads best
  in one place), at most 8 parameters besides keyword-only option objects (a
  keyword-only parameter annotated ``...Options``).

Each check collects every offender and fails once with the whole list, so one run
shows all that is left to do.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "manip_id"

#: Libraries a function may import locally: optional, heavy, or slow to import (the
#: CLI's ``--help`` should cost little more than ``import pinocchio``).
HEAVY = {
    "matplotlib",  # figures
    "meshcat",  # 3-D scenes
    "pinocchio.visualize",  # the meshcat visualizer
    "cvxpy",  # the SDP of the consistent estimate
    "dask",  # fleet back-end
    "distributed",
    "rosbags",  # ROS 2 bags
    "scipy.signal",
    "scipy.optimize",
    "scipy.stats",
    "scipy.interpolate",
    "mujoco",
    "numba",
    "threadpoolctl",  # one BLAS thread in the log-Cholesky solver (optional)
    "tqdm",
    "psutil",  # memory budgets
    "example_robot_data",  # its robot index, for robots loaded by name
    "tomllib",  # profiles (the tomli backport on Python 3.10)
    "tomli",
    "webbrowser",  # opening a report only when asked
    "manip_id.robot._regressor_kernel",  # numba kernels: imports numba at module level
    "manip_id.signals._filter_kernel",  # the compiled zero-phase filter: imports numba
    "manip_id.datasets._csv_kernel",  # the compiled CSV reader: imports numba
}
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80
MAX_PARAMETERS = 8


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _sources() -> dict[str, tuple[Path, ast.Module]]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        out[_module_name(path)] = (path, ast.parse(path.read_text(encoding="utf-8")))
    return out


SOURCES = _sources()


def _is_package(name: str) -> bool:
    return SOURCES[name][0].name == "__init__.py"


def _resolve(module: str, node: ast.ImportFrom) -> str:
    """The absolute module name of ``from [.]*x import ...`` inside ``module``."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    if not _is_package(module):
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _type_checking_nodes(tree: ast.Module) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for sub in node.body:
                skip.update(id(n) for n in ast.walk(sub))
    return skip


class _Imports(ast.NodeVisitor):
    """Every import of a module: (target module, imported names, line, in a function)."""

    def __init__(self, module: str, tree: ast.Module):
        self.module, self.depth, self.found = module, 0, []
        self.skip = _type_checking_nodes(tree)

    def _function(self, node):
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = _function

    def visit_Import(self, node):
        if id(node) not in self.skip:
            for alias in node.names:
                self.found.append((alias.name, [], node.lineno, self.depth > 0))

    def visit_ImportFrom(self, node):
        if id(node) not in self.skip:
            target = _resolve(self.module, node)
            names = [a.name for a in node.names]
            self.found.append((target, names, node.lineno, self.depth > 0))


def _imports(module: str):
    tree = SOURCES[module][1]
    v = _Imports(module, tree)
    v.visit(tree)
    return v.found


def _internal(target: str, names: list[str]) -> list[str]:
    """The manip_id modules an import loads (``from .pkg import sub`` loads ``pkg.sub``)."""
    if target not in SOURCES:
        return []
    out = [target]
    for n in names:
        if f"{target}.{n}" in SOURCES:
            out.append(f"{target}.{n}")
    return out


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = defaultdict(set)
    for module in SOURCES:
        for target, names, _, _ in _imports(module):
            for dep in _internal(target, names):
                if dep != module:
                    graph[module].add(dep)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
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
                out.append(sorted(comp))

    for v in sorted(SOURCES):
        if v not in index:
            visit(v)
    return out


def _report(title: str, offenders: list[str]) -> None:
    if offenders:
        pytest.fail(f"{title} ({len(offenders)}):\n  " + "\n  ".join(offenders), pytrace=False)


def test_the_scan_sees_the_package():
    assert {"manip_id", "manip_id.identification", "manip_id.execution"} <= set(SOURCES)
    graph = _graph()
    assert "manip_id.identification.solve" in graph["manip_id.identification.front"]
    assert "manip_id.errors" in graph["manip_id.identification.solve"]


def test_no_import_cycles():
    cycles = _cycles(_graph())
    _report("import cycles (module-level and function-local imports)", [
        " <-> ".join(c) for c in cycles
    ])  # fmt: skip


def _heavy(target: str) -> bool:
    return any(target == h or target.startswith(h + ".") for h in HEAVY)


def test_function_local_imports_are_optional_heavy_libraries_only():
    offenders = []
    for module in SOURCES:
        for target, _names, line, local in _imports(module):
            if local and not _heavy(target):
                offenders.append(f"{module}:{line} imports {target} inside a function")
    _report("function-local imports of non-heavy modules", offenders)


class _PrivateAttributes(ast.NodeVisitor):
    """``alias._name`` where ``alias`` is an imported manip_id module."""

    def __init__(self, aliases: dict[str, str]):
        self.aliases, self.found = aliases, []

    def visit_Attribute(self, node):
        if (
            isinstance(node.value, ast.Name)
            and node.value.id in self.aliases
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            self.found.append((node.lineno, f"{self.aliases[node.value.id]}.{node.attr}"))
        self.generic_visit(node)


def test_no_private_names_across_modules():
    offenders = []
    for module, (_path, tree) in SOURCES.items():
        aliases: dict[str, str] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _resolve(module, node)
                for a in node.names:
                    sub = f"{target}.{a.name}"
                    if sub in SOURCES:
                        aliases[a.asname or a.name] = sub
                    elif target in SOURCES and target != module and a.name.startswith("_"):
                        if not a.name.startswith("__"):
                            offenders.append(f"{module}:{node.lineno} imports {target}.{a.name}")
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name in SOURCES and a.asname:
                        aliases[a.asname] = a.name
        v = _PrivateAttributes({k: m for k, m in aliases.items() if m != module})
        v.visit(tree)
        offenders += [f"{module}:{line} uses {name}" for line, name in v.found]
    _report("private names used across modules", offenders)


def test_module_sizes():
    offenders = []
    for module, (path, _) in SOURCES.items():
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_MODULE_LINES:
            offenders.append(f"{module}: {n} lines")
    _report(f"modules over {MAX_MODULE_LINES} lines", offenders)


def _declares_arguments(fn: ast.AST) -> bool:
    return any(
        isinstance(n, ast.Call)
        and isinstance(n.func, ast.Attribute)
        and n.func.attr == "add_argument"
        for n in ast.walk(fn)
    )


def _functions():
    for module, (_path, tree) in SOURCES.items():
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield module, node


def _code_lines(fn) -> int:
    """Lines from ``def`` to the end, less the docstring's."""
    n = fn.end_lineno - fn.lineno + 1
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        if isinstance(body[0].value.value, str):
            n -= body[0].end_lineno - body[0].lineno + 1
    return n


def test_function_sizes():
    offenders = []
    for module, fn in _functions():
        n = _code_lines(fn)
        if n > MAX_FUNCTION_LINES and not _declares_arguments(fn):
            offenders.append(f"{module}.{fn.name} (line {fn.lineno}): {n} lines")
    _report(
        f"functions over {MAX_FUNCTION_LINES} lines (argparse declarations excepted)", offenders
    )


def _is_option_object(arg: ast.arg) -> bool:
    return arg.annotation is not None and "Options" in ast.unparse(arg.annotation)


def test_parameter_counts():
    offenders = []
    for module, fn in _functions():
        a = fn.args
        params = [*a.posonlyargs, *a.args, *[k for k in a.kwonlyargs if not _is_option_object(k)]]
        params = [p for p in params if p.arg not in ("self", "cls")]
        if len(params) > MAX_PARAMETERS:
            offenders.append(f"{module}.{fn.name} (line {fn.lineno}): {len(params)} parameters")
    _report(
        f"functions with more than {MAX_PARAMETERS} parameters besides option objects", offenders
    )


def test_the_checks_bite():
    """The scan finds a cycle, a private import and a local import in made-up modules."""
    fake = {
        "manip_id.fake_a": ast.parse(
            "from .fake_b import _x\ndef f():\n    from . import fake_b\n"
        ),
        "manip_id.fake_b": ast.parse("from . import fake_a\n"),
    }
    saved = dict(SOURCES)
    try:
        for name, tree in fake.items():
            SOURCES[name] = (PACKAGE / (name.split(".")[1] + ".py"), tree)
        assert ["manip_id.fake_a", "manip_id.fake_b"] in _cycles(_graph())
        found = _imports("manip_id.fake_a")
        assert ("manip_id.fake_b", ["_x"], 1, False) in found
        assert ("manip_id", ["fake_b"], 3, True) in found
    finally:
        SOURCES.clear()
        SOURCES.update(saved)


def _layers_module():
    """docs/layers.py, the one table of layers (loaded by path: docs/ is not a package)."""
    import importlib.util

    path = PACKAGE.parent / "docs" / "layers.py"
    spec = importlib.util.spec_from_file_location("_manip_id_layers", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


LAYERS = _layers_module()


def _layer(module: str) -> int | None:
    return LAYERS.layer_of(module.removeprefix("manip_id").removeprefix("."))


def test_every_module_has_a_layer():
    missing = [m for m in SOURCES if _layer(m) is None]
    _report("modules in no layer of docs/layers.py", missing)


def test_no_upward_imports():
    """A module imports only its own layer or lower ones (function-local imports too)."""
    offenders = []
    names = [layer for layer, _doc, _prefixes in LAYERS.LAYERS]
    for module in SOURCES:
        mine = _layer(module)
        for target, imported, line, _local in _imports(module):
            for dep in _internal(target, imported):
                theirs = _layer(dep)
                if mine is not None and theirs is not None and theirs > mine:
                    offenders.append(
                        f"{module}:{line} ({names[mine]}) imports {dep} ({names[theirs]})"
                    )
    _report("imports of a higher layer", offenders)


def test_layout_page_is_generated_from_the_tree():
    text = LAYERS.LAYOUT.read_text(encoding="utf-8")
    assert LAYERS.MARKER in text
    assert (
        text.split(LAYERS.MARKER)[1].strip() == LAYERS.tables().split(LAYERS.MARKER)[1].strip()
    ), "docs/layout.md has drifted from the tree: run python docs/layers.py"


def _is_shim(tree: ast.Module) -> bool:
    """A module that only re-exports: docstring, imports, ``__all__`` and nothing else."""
    body = [
        n
        for n in tree.body
        if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))
        and not isinstance(n, (ast.Import, ast.ImportFrom))
        and not (
            isinstance(n, ast.Assign) and [getattr(t, "id", None) for t in n.targets] == ["__all__"]
        )
    ]
    has_imports = any(isinstance(n, ast.ImportFrom) and n.level for n in tree.body)
    return has_imports and not body


def test_no_shim_modules():
    """No module kept only to re-export another's names under an old path (nothing was
    released); a package's ``__init__`` may gather its own modules' names."""
    offenders = [
        m for m, (path, tree) in SOURCES.items() if path.name != "__init__.py" and _is_shim(tree)
    ]
    _report("modules that only re-export", offenders)


def test_the_layer_checks_bite():
    """An import from robot/ of identification/ is upward; a re-export module is a shim."""
    assert _layer("manip_id.robot.model") < _layer("manip_id.identification.solve")
    assert _layer("manip_id.errors") == 0
    assert _is_shim(ast.parse('"""Old path."""\nfrom .x import a\n__all__ = ["a"]\n'))
    assert not _is_shim(ast.parse("from .x import a\n\ndef f():\n    return a\n"))
