"""The package's modules, and its top-level packages, import each other without a cycle, counting
imports inside functions (a deferred import hides a cycle from Python but not from a reader); and
the layers of ``docs/layout.md`` hold: ``lint-imports`` (import-linter) keeps the contracts of
``pyproject.toml``."""

from __future__ import annotations

import ast
import importlib.util
import os
import shutil
import subprocess
import sys
import tomllib
from graphlib import CycleError, TopologicalSorter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"


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


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """Top-level package (or module) of ``quadest`` → the top-level packages its modules import,
    from a module graph of :func:`import_graph` (the root ``quadest`` itself left out)."""

    def top(module: str) -> str:
        return ".".join(module.split(".")[:2])

    packages: dict[str, set[str]] = {}
    for module, deps in graph.items():
        if module == "quadest":
            continue
        packages.setdefault(top(module), set()).update(top(d) for d in deps if d != "quadest" and top(d) != top(module))
    return packages


def test_no_package_import_cycle():
    """The layers of docs/layout.md need more than acyclic modules: no two top-level packages may
    import each other, even through different modules."""
    try:
        tuple(TopologicalSorter(package_graph(import_graph(SRC))).static_order())
    except CycleError as exc:
        raise AssertionError(f"package import cycle: {' -> '.join(exc.args[1])}") from None


def test_the_package_graph_sees_a_cycle_that_no_module_has(tmp_path):
    package = tmp_path / "quadest"
    for sub in ("low", "high"):
        (package / sub).mkdir(parents=True)
        (package / sub / "__init__.py").write_text("")
    (package / "__init__.py").write_text("")
    (package / "low" / "a.py").write_text("from quadest.high.c import h\n")
    (package / "high" / "b.py").write_text("from quadest.low.d import g\n")
    (package / "low" / "d.py").write_text("")
    (package / "high" / "c.py").write_text("")
    graph = import_graph(tmp_path)
    tuple(TopologicalSorter(graph).static_order())  # the modules have no cycle
    assert package_graph(graph) == {"quadest.low": {"quadest.high"}, "quadest.high": {"quadest.low"}}


needs_import_linter = pytest.mark.skipif(
    importlib.util.find_spec("importlinter") is None, reason="import-linter is not installed (pip install '.[test]')"
)


def lint_imports(src: Path, cwd: Path) -> subprocess.CompletedProcess:
    """``lint-imports`` (import-linter's command) with the contracts of ``pyproject.toml`` on the
    ``quadest`` package found in ``src``; no cache is written."""
    command = [sys.executable, "-c", "from importlinter.cli import lint_imports_command; lint_imports_command()"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(src), os.environ.get("PYTHONPATH", "")]), "COLUMNS": "200"}
    args = ["--no-cache", str(ROOT / "pyproject.toml")]
    return subprocess.run([*command, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


def contract_names() -> dict[str, str]:
    """Contract id → name, from ``[tool.importlinter]`` of ``pyproject.toml``."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    return {c["id"]: c["name"] for c in config["tool"]["importlinter"]["contracts"]}


@needs_import_linter
def test_import_contracts_are_kept(tmp_path):
    done = lint_imports(SRC, tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"Contracts: {len(contract_names())} kept, 0 broken." in done.stdout, done.stdout


@needs_import_linter
@pytest.mark.parametrize(
    ("module", "text", "contract"),
    [
        ("numerics/upward.py", "from quadest.evaluation.metrics import summarize\n", "layers"),
        ("models/upward.py", "def f():\n    from quadest.simulation.registry import build_data\n", "layers"),
        ("unplaced.py", "", "layers"),  # a new top-level module must be given a layer
        ("evaluation/upward.py", "from quadest.runner import run_estimator\n", "results-without-runner"),
        ("estimators/upward.py", "from quadest.montecarlo import MonteCarloData\n", "estimators-see-the-model-only"),
        ("sensors/upward.py", "from omegaconf import OmegaConf\n", "hydra-in-app-only"),
        ("aggregate/upward.py", "from hydra.experimental.callback import Callback\n", "hydra-in-app-only"),
    ],
)
def test_a_forbidden_import_breaks_its_contract(tmp_path, module, text, contract):
    """The check can fail: on a copy of the package, one module added with an import that a
    contract forbids makes ``lint-imports`` fail, with that contract broken and the others kept."""
    copy = tmp_path / "src"
    shutil.copytree(SRC / "quadest", copy / "quadest", ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "quadest" / module).write_text(f'"""An import a contract forbids."""\n\n{text}')
    done = lint_imports(copy, tmp_path)
    assert done.returncode != 0, done.stdout + done.stderr
    assert f"{contract_names()[contract]} BROKEN" in done.stdout, done.stdout
    assert f"Contracts: {len(contract_names()) - 1} kept, 1 broken." in done.stdout, done.stdout
