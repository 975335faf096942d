"""Tests that fail when the package layout rots (issue 13, "One house").

They read the source with :mod:`ast` and never import it, except (d), which imports the package in a fresh
interpreter. Each failure names what is wrong: the cycle, the file and private name, the long function.

* (a) no import cycles among matremap's modules;
* (b) no private name (leading underscore) imported from another matremap module;
* (c) every function over :data:`MAX_LINES` lines says why in its docstring, on a line that starts with
  ``Long:`` followed by the reason, e.g. ``Long: one branch per glTF extension, read in file order.``;
* (d) ``import matremap, matremap.cli`` loads no heavy optional dependency.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

PACKAGE = "matremap"
SOURCE = Path(__file__).resolve().parents[1] / "src" / PACKAGE
MAX_LINES = 80
LONG_REASON = re.compile(r"^\s*Long:\s*\S", re.MULTILINE)
HEAVY = ("mitsuba", "drjit", "bpy", "sklearn", "dask", "distributed", "MaterialX")


@dataclass(frozen=True)
class Module:
    """One module of the package: its dotted name, file and syntax tree."""

    name: str
    path: Path
    tree: ast.Module

    @property
    def is_package(self) -> bool:
        """Whether this is a package's ``__init__``."""
        return self.path.name == "__init__.py"

    @property
    def where(self) -> str:
        """The file from the folder that holds the package (``matremap/core/fit.py``), for messages."""
        root = self.path.parents[self.name.count(".") + int(self.is_package)]
        return str(self.path.relative_to(root))


Modules = dict[str, Module]


def load_modules(root: Path) -> Modules:
    """Every module of the package in folder ``root`` by dotted name (a package's ``__init__`` under the
    package's own name)."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        parts = (root.name, *path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        name = ".".join(parts)
        found[name] = Module(name, path, ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
    return found


@cache
def matremap_modules() -> Modules:
    """The modules under src/matremap, parsed once per session."""
    return load_modules(SOURCE)


def is_type_checking_block(node: ast.If) -> bool:
    """``if TYPE_CHECKING:`` (or ``typing.TYPE_CHECKING``): imports under it never run."""
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def import_nodes(nodes: Iterable[ast.AST]) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement anywhere under ``nodes`` (module level, functions, classes), except in the body of
    an ``if TYPE_CHECKING:`` block, which is for the type checker and never runs (its ``else`` does)."""
    for node in nodes:
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        elif isinstance(node, ast.If) and is_type_checking_block(node):
            yield from import_nodes(node.orelse)
        else:
            yield from import_nodes(ast.iter_child_nodes(node))


def from_base(module: Module, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` reads from, with relative imports resolved."""
    if not node.level:
        return node.module or ""
    package = module.name.split(".") if module.is_package else module.name.split(".")[:-1]
    base = package[: len(package) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def known(name: str, table: Modules) -> str | None:
    """``name`` if it is a module of the package, else its longest prefix that is, else None."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in table:
            return candidate
    return None


def imported_modules(module: Module, table: Modules) -> set[str]:
    """The package modules that ``module`` imports: ``import a.b`` imports a.b; ``from a import b`` imports a.b
    when that is a module, else a."""
    targets: set[str | None] = set()
    for node in import_nodes([module.tree]):
        if isinstance(node, ast.Import):
            targets.update(known(alias.name, table) for alias in node.names)
            continue
        base = from_base(module, node)
        for alias in node.names:
            submodule = f"{base}.{alias.name}"
            targets.add(submodule if submodule in table else known(base, table))
    return {t for t in targets if t is not None and t != module.name}


def import_graph(table: Modules) -> dict[str, set[str]]:
    """Module name -> the package modules it imports."""
    return {name: imported_modules(module, table) for name, module in table.items()}


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one module, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return components


def shortest_cycle(graph: dict[str, set[str]], start: str, members: set[str]) -> list[str]:
    """The shortest import path from ``start`` back to itself inside one component (breadth first)."""
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in sorted(graph[v] & members):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [start, *reversed(path[:-1]), start]
                if w not in previous:
                    previous[w] = v
                    following.append(w)
        frontier = following
    raise AssertionError(f"{start} is in a component but on no cycle")


def import_cycles(table: Modules) -> list[str]:
    """One line per group of modules that import each other (a strongly connected component): its shortest
    cycle through the group's first module, then every module in the group."""
    graph = import_graph(table)
    return [
        " -> ".join(shortest_cycle(graph, component[0], set(component)))
        + f"  (the group: {len(component)} modules, {', '.join(component)})"
        for component in strongly_connected(graph)
    ]


def is_private(name: str) -> bool:
    """A leading underscore, but not a dunder such as ``__version__``."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(module: Module, table: Modules) -> Iterator[str]:
    """``file:line name`` for every private name this module takes from another package module: by
    ``from ... import _name``, by ``import a._b``, or as ``alias._name`` on a module it imported."""
    module_aliases: set[str] = set()
    for node in import_nodes([module.tree]):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if known(alias.name, table) is None:
                    continue
                if any(is_private(part) for part in alias.name.split(".")):
                    yield f"{module.where}:{node.lineno} {alias.name}"
                module_aliases.add(alias.asname or alias.name)
            continue
        base = from_base(module, node)
        if known(base, table) is None:
            continue
        if any(is_private(part) for part in base.split(".")):
            yield f"{module.where}:{node.lineno} {base}"
        for alias in node.names:
            if is_private(alias.name):
                yield f"{module.where}:{node.lineno} {base}.{alias.name}"
            elif f"{base}.{alias.name}" in table:
                module_aliases.add(alias.asname or alias.name)
    for node in ast.walk(module.tree):
        if isinstance(node, ast.Attribute) and is_private(node.attr) and ast.unparse(node.value) in module_aliases:
            yield f"{module.where}:{node.lineno} {ast.unparse(node)}"


def long_functions(table: Modules) -> Iterator[tuple[str, int]]:
    """``(file:line qualified.name, lines)`` of every function over MAX_LINES lines whose docstring gives no
    ``Long:`` reason. Lines run from the ``def`` to the function's last line, decorators excluded."""

    def walk(node: ast.AST, prefix: str, module: Module) -> Iterator[tuple[str, int]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                name = f"{prefix}{child.name}"
                lines = (child.end_lineno or child.lineno) - child.lineno + 1
                if lines > MAX_LINES and not LONG_REASON.search(ast.get_docstring(child) or ""):
                    yield f"{module.where}:{child.lineno} {name}", lines
                yield from walk(child, f"{name}.", module)
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, f"{prefix}{child.name}.", module)
            else:
                yield from walk(child, prefix, module)

    for module in table.values():
        yield from walk(module.tree, "", module)


# --- the package -------------------------------------------------------------------------------------------------


def test_the_walk_finds_the_package() -> None:
    # guards the tests below against passing vacuously on a moved source tree
    graph = import_graph(matremap_modules())
    assert {"matremap", "matremap.core.models", "matremap.cli"} <= set(graph)
    assert "matremap.core.material" in graph["matremap"]


def test_no_import_cycles() -> None:
    cycles = import_cycles(matremap_modules())
    assert not cycles, "import cycles among matremap's modules (imports inside functions count):\n" + "\n".join(cycles)


def test_no_private_names_imported_across_modules() -> None:
    table = matremap_modules()
    found = [hit for module in table.values() for hit in private_imports(module, table)]
    assert not found, (
        "private names taken from other matremap modules (make them public with a docstring, or move them):\n"
        + "\n".join(found)
    )


def test_long_functions_say_why() -> None:
    found = sorted(long_functions(matremap_modules()), key=lambda hit: -hit[1])
    assert not found, (
        f"functions over {MAX_LINES} lines without a reason (a docstring line starting 'Long: <why>'):\n"
        + "\n".join(f"{lines:4d} lines  {where}" for where, lines in found)
    )


def test_import_loads_no_heavy_optional_dependency() -> None:
    script = (
        "import json, sys\n"
        "import matremap, matremap.cli\n"
        f"heavy = {HEAVY!r}\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in heavy)))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert not loaded, f"`import matremap, matremap.cli` loads optional dependencies: {', '.join(loaded)}"


# --- the checkers, on a small package made for them --------------------------------------------------------------


def write_package(root: Path, files: dict[str, str]) -> Modules:
    """Write ``files`` (path inside the package -> source) under ``root`` and load them."""
    for relative, text in files.items():
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return load_modules(root)


def test_checkers_find_cycles_through_functions_and_relative_imports(tmp_path: Path) -> None:
    table = write_package(
        tmp_path / "pkg",
        {
            "__init__.py": "from pkg.a import f\n",
            "a.py": "def f():\n    from . import b\n",  # inside a function, relative: pkg.b
            "b.py": "from .sub import c\n",  # a submodule: pkg.sub.c, not pkg.sub
            "sub/__init__.py": "",
            "sub/c.py": "from ..a import f\nimport pkg.d\n",
            "d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.sub.c\nelse:\n    import os\n",
        },
    )
    graph = import_graph(table)
    assert graph["pkg"] == {"pkg.a"}
    assert graph["pkg.a"] == {"pkg.b"}
    assert graph["pkg.b"] == {"pkg.sub.c"}
    assert graph["pkg.sub.c"] == {"pkg.a", "pkg.d"}
    assert graph["pkg.d"] == set()  # type-checking imports never run
    assert import_cycles(table) == [
        "pkg.a -> pkg.b -> pkg.sub.c -> pkg.a  (the group: 3 modules, pkg.a, pkg.b, pkg.sub.c)"
    ]


def test_checkers_find_private_names(tmp_path: Path) -> None:
    table = write_package(
        tmp_path / "pkg",
        {
            "__init__.py": "from pkg.a import __version__, f as _f\n",  # a dunder and a private alias are fine
            "a.py": "__version__ = '1'\ndef f(): ...\ndef _g(): ...\n",
            "b.py": "from pkg.a import f, _g\nfrom . import _h\nimport pkg.a as a\na._g()\nimport os\nos._exit\n",
            "_h.py": "",
        },
    )
    found = [hit for module in table.values() for hit in private_imports(module, table)]
    assert found == ["pkg/b.py:1 pkg.a._g", "pkg/b.py:2 pkg._h", "pkg/b.py:4 a._g"]


def function_source(name: str, lines: int, docstring: str = "", indent: str = "") -> str:
    """A function ``lines`` lines long (its ``def`` included), with a one-line docstring if given."""
    head = [f"def {name}():"] + ([f'    """{docstring}"""'] if docstring else [])
    body = ["    x = 1"] * (lines - len(head))
    return "".join(f"{indent}{line}\n" for line in head + body)


def test_checkers_find_long_functions(tmp_path: Path) -> None:
    a = (
        function_source("fits", MAX_LINES)
        + function_source("too_long", MAX_LINES + 1)
        + function_source("says_why", MAX_LINES + 1, "Long: one step per field, in file order.")
        + "class C:\n"
        + function_source("method", MAX_LINES + 2, "Long:", indent="    ")
    )
    table = write_package(tmp_path / "pkg", {"__init__.py": "", "a.py": a})
    assert sorted(long_functions(table)) == [("pkg/a.py:244 C.method", 82), ("pkg/a.py:81 too_long", 81)]


def test_long_reason_convention() -> None:
    assert LONG_REASON.search('Render the probe.\n\nLong: one branch per lobe, in the order "Cycles" mixes them.')
    assert not LONG_REASON.search("Render the probe.\n\nLong:")
    assert not LONG_REASON.search("Render as long: as it takes.")
