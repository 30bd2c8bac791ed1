"""The package's modules import each other without a cycle, counting imports inside functions
(a deferred import hides a cycle from Python but not from a reader)."""

from __future__ import annotations

import ast
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"


def import_graph(src: Path) -> dict[str, set[str]]:
    """Module → the package modules it imports anywhere in its text (a package counts as its
    ``__init__``; a module's own parent packages are left out, Python imports them first anyway)."""
    modules = {}
    for path in (src / "quadest").rglob("*.py"):
        parts = path.relative_to(src).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in modules.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                deps |= {f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module
                         for a in node.names}  # fmt: skip
            elif isinstance(node, ast.Import):
                deps |= {a.name for a in node.names}
        graph[name] = {d for d in deps if d in modules and d != name and not name.startswith(f"{d}.")}
    return graph


def test_no_import_cycle():
    try:
        tuple(TopologicalSorter(import_graph(SRC)).static_order())
    except CycleError as exc:
        raise AssertionError(f"import cycle: {' -> '.join(exc.args[1])}") from None


def test_the_graph_sees_a_deferred_import_cycle(tmp_path):
    package = tmp_path / "quadest"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from quadest.b import g\n")
    (package / "b.py").write_text("def g():\n    from quadest.a import f\n")
    assert import_graph(tmp_path) == {"quadest": set(), "quadest.a": {"quadest.b"}, "quadest.b": {"quadest.a"}}
