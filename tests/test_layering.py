"""The package's layering (issues 28 and 36): no import circle, the kernels below the code
generator, the caches and the I/O, argparse only in the CLI, no module over
:data:`MAX_LINES` lines, a top level of packages and at most :data:`MAX_TOP_MODULES` plain
modules.

The import graph is read from the sources (``ast``) with every import: at the top of a
module, inside a function (the lazy ones) and under ``if TYPE_CHECKING:``. A lazy import is
a dependency all the same (it runs when its function does), and a ``TYPE_CHECKING`` one is a
dependency of the code's meaning (the reader and the type checker follow it): two modules in
a circle through any of them cannot be read, moved or tested one without the other. This is
also the graph ``walk.py`` places modules on floors by. An edge goes to the module named
(``from a.b import c``: to ``a.b.c`` if that is a module, else to ``a.b``), not to the
packages on the way: a package's ``__init__`` re-exports its submodules, which import each
other through their own names.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "mcchain"

PLAIN = {"mcchain.codes", "mcchain.contact", "mcchain.folders", "mcchain.status"}
"""Modules of constants and helpers outside ``mcchain/kernels`` that the kernels may import:
each imports nothing of mcchain (asserted), so no codegen, cache or I/O module either
(:mod:`mcchain.folders`: a writable, private folder for numba's cache)."""

KERNELS_MAY_IMPORT = PLAIN
"""The kernels read the Model's codes from :mod:`mcchain.codes` and take its arrays as a
NamedTuple (:class:`mcchain.model.KernelModel`), never importing the Model itself."""


MAX_LINES = 700
"""Lines a module of mcchain/ may have: past that it holds more than one job (issue 28)."""

MAX_TOP_MODULES = 8
"""Plain modules mcchain/ may hold beside its packages (constants, errors, the model): the
packages name the parts (issue 36)."""

ALLOWED_CIRCLES = [{"mcchain.scene.models", "mcchain.scene.outputs"}]
"""Circles the lead removes at merge: scene/outputs (h-outputs, merged while issue 36 was
under way) defines ``Output`` for scene/models and checks a whole ``Scene`` (typed by a
``TYPE_CHECKING`` import of scene/models); its checks would go beside scene/checks."""


def _module_files() -> dict[str, Path]:
    files = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        files[".".join(parts)] = path
    return files


def _runtime_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """The import statements of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def _all_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of ``tree``, ``if TYPE_CHECKING:`` blocks included."""
    return [node for node in ast.walk(tree) if isinstance(node, ast.Import | ast.ImportFrom)]


def _imported_names(module: str, path: Path, node: ast.Import | ast.ImportFrom) -> list[str]:
    """The absolute names an import statement of ``module`` (file ``path``) imports."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = node.module or ""
    if node.level:
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        package = package[: len(package) - node.level + 1]
        base = ".".join([*package, base] if base else package)
    return [f"{base}.{alias.name}" for alias in node.names]


def import_graph(type_checking: bool = False) -> dict[str, set[str]]:
    """``{module: the mcchain modules it imports}`` (``mcchain`` itself left out), at run
    time, or with ``type_checking`` also under ``if TYPE_CHECKING:``."""
    files = _module_files()
    graph: dict[str, set[str]] = {}
    imports = _all_imports if type_checking else _runtime_imports
    for module, path in files.items():
        edges: set[str] = set()
        for node in imports(ast.parse(path.read_text())):
            for name in _imported_names(module, path, node):
                while name and name not in files:  # a name in a module: that module
                    name = name.rpartition(".")[0]
                if name and name not in (module, "mcchain"):
                    edges.add(name)
        graph[module] = edges
    return graph


def _circles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[set[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(component)

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return found


def test_layering__no_import_circle():
    """Counting every import (see the module's docstring)."""
    graph = import_graph(type_checking=True)
    circles = [
        f"{a} -> {b}"
        for component in _circles(graph)
        if component not in ALLOWED_CIRCLES
        for a in sorted(component)
        for b in sorted(graph[a] & component)
    ]
    assert not circles, "import circles:\n" + "\n".join(circles)


def test_circles__found_in_a_toy_graph():
    """The finder itself: a three-module circle and a two-module one, not the tail."""
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a", "e"}, "e": {"d"}, "f": {"a"}}
    assert sorted(map(sorted, _circles(graph))) == [["a", "b", "c"], ["d", "e"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


def test_layering__kernels_import_no_cache_module_even_for_types():
    graph = import_graph(type_checking=True)
    outside = {
        f"{module} -> {target}"
        for module, targets in graph.items()
        if module.startswith("mcchain.kernels")
        for target in targets
        if not target.startswith("mcchain.kernels") and target not in KERNELS_MAY_IMPORT
    }
    assert not outside
    assert not {module: graph[module] for module in PLAIN if graph[module]}


def test_layering__top_level_is_packages_and_a_few_plain_modules():
    top = [p for p in PACKAGE.iterdir() if p.suffix == ".py" and p.name != "__init__.py"]
    assert len(top) <= MAX_TOP_MODULES, sorted(p.name for p in top)
    packages = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    assert {"runner", "compiled", "scene", "kernels", "solvers", "ensemble"} <= packages


def test_layering__argparse_only_in_the_cli():
    users = set()
    for module, path in _module_files().items():
        for node in _runtime_imports(ast.parse(path.read_text())):
            if any(n.split(".")[0] == "argparse" for n in _imported_names(module, path, node)):
                users.add(module)
    assert users and all(m == "mcchain.cli" or m.startswith("mcchain.cli.") for m in users), users


def test_layering__no_module_over_max_lines():
    lines = {module: len(path.read_text().splitlines()) for module, path in _module_files().items()}
    long = {m: n for m, n in lines.items() if n > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"
