"""The package's layering (issue 28): no import circle, the kernels below the code generator,
the caches and the I/O, argparse only in the CLI, no module over :data:`MAX_LINES` lines.

The import graph is read from the sources (``ast``), with the imports inside functions (the
lazy ones) and without those under ``if TYPE_CHECKING:`` (never executed). An edge goes to
the module named (``from a.b import c``: to ``a.b.c`` if that is a module, else to ``a.b``),
not to the packages on the way: a package's ``__init__`` re-exports its submodules, which
import each other through their own names.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "mcchain"

PLAIN = {"mcchain.compiled.caches", "mcchain.codes", "mcchain.contact", "mcchain.status"}
"""Modules of constants and helpers outside ``mcchain/kernels`` that the kernels may import:
each imports nothing of mcchain (asserted), so no codegen, cache or I/O module either."""

KERNELS_MAY_IMPORT = PLAIN
"""The kernels read the Model's codes from :mod:`mcchain.codes` and take its arrays as a
NamedTuple (:class:`mcchain.model.KernelModel`), never importing the Model itself."""


MAX_LINES = 700
"""Lines a module of mcchain/ may have: past that it holds more than one job (issue 28)."""


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


def import_graph() -> dict[str, set[str]]:
    """``{module: the mcchain modules it imports}`` (``mcchain`` itself left out)."""
    files = _module_files()
    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        edges: set[str] = set()
        for node in _runtime_imports(ast.parse(path.read_text())):
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
    graph = import_graph()
    circles = [
        f"{a} -> {b}"
        for component in _circles(graph)
        for a in sorted(component)
        for b in sorted(graph[a] & component)
    ]
    assert not circles, "import circles:\n" + "\n".join(circles)


def test_layering__kernels_import_no_codegen_cache_or_io():
    graph = import_graph()
    outside = {
        f"{module} -> {target}"
        for module, targets in graph.items()
        if module.startswith("mcchain.kernels")
        for target in targets
        if not target.startswith("mcchain.kernels") and target not in KERNELS_MAY_IMPORT
    }
    assert not outside
    assert not {module: graph[module] for module in PLAIN if graph[module]}


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
