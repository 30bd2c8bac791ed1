"""Provenance on every install path (quadest.app.provenance, tools/hatch_build.py): a checkout is
described by git at run time; a non-editable install by the record its build wrote (the commit,
and whether the tree differed from it), and says so; without either, the commit is unknown and the
summary says why. tools/regenerate_results.py runs the clone's own code or refuses."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORCE_INCLUDED = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["hatch"]["build"]["targets"]["wheel"][
    "force-include"
]
SOURCE = ["pyproject.toml", "README.md", "src", "tools/hatch_build.py", *FORCE_INCLUDED]
"""What a wheel is built from: the package, the build hook and every folder the wheel force-includes."""
PROBE = "import json, quadest.app.provenance as p; print(json.dumps(p.provenance()))"

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="needs git")


def _git(repo: Path, *args: str) -> str:
    env = {**os.environ, "GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
           "GIT_COMMITTER_EMAIL": "t@t"}  # fmt: skip
    return subprocess.run(["git", *args], cwd=repo, env=env, capture_output=True, text=True, check=True).stdout.strip()


@pytest.fixture(scope="module")
def repo(tmp_path_factory) -> Path:
    """A fresh git repository holding the package's source tree, one commit."""
    repo = tmp_path_factory.mktemp("repo")
    for name in SOURCE:
        source, target = ROOT / name, repo / name
        target.parent.mkdir(parents=True, exist_ok=True)
        if source.is_dir():
            shutil.copytree(source, target, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(source, target)
    _git(repo, "init", "-q")
    _git(repo, "add", "-A")
    _git(repo, "commit", "-q", "-m", "tree")
    return repo


def _wheel(repo: Path, out: Path) -> Path:
    command = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(out)]
    command.append(str(repo))
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return next(out.glob("quadest-*.whl"))


def _record(wheel: Path) -> dict:
    with zipfile.ZipFile(wheel) as archive:
        return json.loads(archive.read("quadest/_build_info.json"))


def _provenance_of(site: Path) -> dict:
    """provenance() of the package unpacked into ``site`` (the way a non-editable install runs it)."""
    env = {**os.environ, "PYTHONPATH": str(site)}
    done = subprocess.run([sys.executable, "-c", PROBE], cwd=site, env=env, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)


def test_a_wheel_records_the_commit_it_was_built_from(repo, tmp_path):
    record = _record(_wheel(repo, tmp_path / "clean"))
    assert record["commit"] == _git(repo, "rev-parse", "HEAD") and record["commit_dirty"] is False


def test_a_wheel_built_from_an_edited_tree_says_so(repo, tmp_path):
    source = repo / "src" / "quadest" / "errors.py"
    original = source.read_text()
    try:
        source.write_text(original + "\n# an edit\n")
        record = _record(_wheel(repo, tmp_path / "dirty"))
    finally:
        source.write_text(original)
    assert record["commit"] == _git(repo, "rev-parse", "HEAD") and record["commit_dirty"] is True


def test_a_non_editable_install_reports_its_build_record_and_says_so(repo, tmp_path):
    """Unpacked inside a git checkout (a virtual environment can sit in a clone), the copy is not
    tracked there: the build record is what it reports, not the surrounding checkout's commit."""
    site = repo / "venv-site"  # untracked
    with zipfile.ZipFile(_wheel(repo, tmp_path / "wheel")) as archive:
        archive.extractall(site)
    _git(repo, "commit", "-q", "--allow-empty", "-m", "a later commit the install never saw")
    got = _provenance_of(site)
    assert got["commit"] == _git(repo, "rev-parse", "HEAD~1") and got["commit_dirty"] is False
    assert got["commit_source"] == "build" and "non-editable" in got["provenance_note"]
    (site / "quadest" / "_build_info.json").unlink()
    got = _provenance_of(site)
    assert got["commit"] == "unknown" and got["commit_dirty"] is None and got["commit_source"] is None
    assert "commit is unknown" in got["provenance_note"]
    shutil.rmtree(site)


def test_a_checkout_is_described_by_git_at_run_time(repo):
    got = _provenance_of(repo / "src")
    assert got["commit"] == _git(repo, "rev-parse", "HEAD") and got["commit_source"] == "git"
    assert "provenance_note" not in got and got["commit_dirty"] is False


@pytest.mark.parametrize(("edited", "dirty"), [("src/quadest/errors.py", True), ("README.md", False)])
def test_a_checkout_with_edited_code_says_so_at_run_time(repo, edited, dirty):
    """An edit to the package's source makes the run's commit dirty; an edit outside the code the
    record covers (``src/``, ``conf/``, ``experiments/``) does not."""
    source = repo / edited
    original = source.read_text()
    try:
        source.write_text(original + "\n# an edit\n")
        got = _provenance_of(repo / "src")
    finally:
        source.write_text(original)
    assert got["commit"] == _git(repo, "rev-parse", "HEAD") and got["commit_dirty"] is dirty


def _regenerate_results():
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import regenerate_results
    finally:
        sys.path.remove(str(ROOT / "tools"))
    return regenerate_results


def test_regeneration_runs_the_clones_code(repo):
    """Its commands import quadest from the clone's src/, even where another copy is importable."""
    tool = _regenerate_results()
    env = tool.clone_environment(repo)
    done = subprocess.run([sys.executable, "-c", "import quadest; print(quadest.__file__)"], env=env,
                          capture_output=True, text=True, check=True)  # fmt: skip
    assert Path(done.stdout.strip()).resolve() == (repo / "src" / "quadest" / "__init__.py").resolve()


def test_regeneration_refuses_a_clone_whose_code_it_cannot_run(tmp_path):
    with pytest.raises(SystemExit, match="regenerate_results: quadest imports from"):
        _regenerate_results().clone_environment(tmp_path)
