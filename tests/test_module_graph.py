"""No import circles among ikid's and ikid_training's modules (issue #31), as the Rust test
``module_graph`` keeps the core free of them.

Every import in every module of ``python/ikid`` and ``training/ikid_training`` counts, wherever
it is written: at the top, inside a function (a lazy import defers a circle, it does not
remove it), in a ``try``. Two kinds do not, because they never run when the module is
imported: those under ``if TYPE_CHECKING:`` (type hints only) and those under
``if __name__ == "__main__":`` (run only when the file is the program, as a module of its own).
An import of a module's own parent package is not an edge either: the parent is initialised
before any of its modules, whatever they import (the rule import-linter follows).

A circle fails the test, named with the import lines that close it.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"ikid": ROOT / "python" / "ikid", "ikid_training": ROOT / "training" / "ikid_training"}


def modules() -> dict[str, Path]:
    """Module name -> source file, for every module of the packages (extension modules by
    their stubs, which import nothing that matters here)."""
    found: dict[str, Path] = {}
    for package, folder in PACKAGES.items():
        for path in sorted(folder.rglob("*.py*")):
            if path.suffix not in (".py", ".pyi") or "__pycache__" in path.parts:
                continue
            parts = [package, *path.relative_to(folder).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            found.setdefault(".".join(parts), path)
    return found


def _skipped(test: ast.expr) -> bool:
    """``TYPE_CHECKING`` / ``typing.TYPE_CHECKING`` or ``__name__ == "__main__"``."""
    if isinstance(test, ast.Name) and test.id == "TYPE_CHECKING":
        return True
    if isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING":
        return True
    return (
        isinstance(test, ast.Compare)
        and isinstance(test.left, ast.Name)
        and test.left.id == "__name__"
        and any(isinstance(c, ast.Constant) and c.value == "__main__" for c in test.comparators)
    )


def imports(tree: ast.AST) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement that can run when the module is imported."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.If) and _skipped(node.test):
            yield from (n for child in node.orelse for n in imports_of(child))
            continue
        yield from imports_of(node)


def imports_of(node: ast.AST) -> Iterator[ast.Import | ast.ImportFrom]:
    if isinstance(node, (ast.Import, ast.ImportFrom)):
        yield node
    else:
        yield from imports(node)


def edges(known: dict[str, Path]) -> dict[str, dict[str, str]]:
    """module -> {imported module: "file:line" of the first import of it}."""
    graph: dict[str, dict[str, str]] = {m: {} for m in known}
    for module, path in known.items():
        if path.suffix != ".py":
            continue
        is_package = path.name == "__init__.py"
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in imports(tree):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                base = node.module or ""
                if node.level:
                    anchor = module.split(".") if is_package else module.split(".")[:-1]
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join([*anchor, *([base] if base else [])])
                targets = [f"{base}.{alias.name}" for alias in node.names] + [base]
            for target in targets:
                # The module itself, or the longest enclosing module that is ours.
                while target and target not in known:
                    target = target.rpartition(".")[0]
                if not target or target == module or module.startswith(target + "."):
                    continue  # not ours, itself, or its own parent package
                where = f"{path.relative_to(ROOT)}:{node.lineno}"
                graph[module].setdefault(target, where)
                if isinstance(node, ast.ImportFrom):
                    break  # `from a.b import c`: the submodule c if it is one, else a.b
    return graph


def circles(graph: dict[str, dict[str, str]]) -> list[list[str]]:
    """One circle (a closed path of modules) per strongly connected group of modules."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(group)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    found = []
    for group in groups:
        members = set(group)
        start = min(group)
        # A shortest way back to the start inside the group (breadth first).
        paths = {start: [start]}
        queue = [start]
        loop = None
        while queue and loop is None:
            v = queue.pop(0)
            for w in sorted(graph[v]):
                if w == start:
                    loop = paths[v] + [start]
                    break
                if w in members and w not in paths:
                    paths[w] = paths[v] + [w]
                    queue.append(w)
        found.append(loop or sorted(group))
    return found


def describe(loop: list[str], graph: dict[str, dict[str, str]]) -> str:
    steps = [f"{a} -> {b} ({graph[a][b]})" for a, b in zip(loop, loop[1:], strict=False)]
    return " -> ".join(loop) + "\n      " + "\n      ".join(steps)


def test_no_module_imports_itself_through_others():
    graph = edges(modules())
    found = circles(graph)
    assert not found, "import circles (move the shared names down, into a module both import):\n  " + (
        "\n  ".join(describe(loop, graph) for loop in found)
    )


def test_the_reader_finds_a_circle_and_its_lines(tmp_path, monkeypatch):
    """The test itself bites: a lazy import inside a function closes a circle and is named;
    the same import under TYPE_CHECKING does not."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.b import thing\n")
    (pkg / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.a import x\n"
        "def thing():\n    from pkg import a\n"
    )
    monkeypatch.setitem(PACKAGES, "pkg", pkg)
    monkeypatch.setattr("test_module_graph.ROOT", tmp_path)
    graph = edges({k: v for k, v in modules().items() if k.startswith("pkg")})
    assert circles(graph) == [["pkg.a", "pkg.b", "pkg.a"]]
    assert graph["pkg.b"] == {"pkg.a": "pkg/b.py:5"}
    (pkg / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.a import x\n"
    )
    assert circles(edges({k: v for k, v in modules().items() if k.startswith("pkg")})) == []
