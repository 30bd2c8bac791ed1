"""Regenerate every checked-in result folder, then the reproductions ledger and the docs' result numbers.

Usage, from the repository root (with quadest's dependencies installed)::

    python tools/regenerate_results.py                 # every folder of results/manifest.yaml, in order
    python tools/regenerate_results.py --only NAME ... # only these folders
    python tools/regenerate_results.py --list          # the folders and their commands, nothing run

Each folder is made afresh: the old folder is moved aside, the folder's commands run in order
(they go through the result cache, so a second regeneration at the same code only reads it), and
the old folder is deleted once every command succeeded, or put back if one failed. Afterwards
``python -m quadest.aggregate.reproductions`` rewrites the ledger (``docs/reproductions.md`` and
``.csv``) and ``python -m quadest.aggregate.doc_numbers`` the result numbers of ``docs/findings.md``
and ``results/README.md`` (``docs/numbers.yaml``) from the new results. The exit status is
non-zero if any command failed.

Every command runs this clone's code: ``src/`` goes first on ``PYTHONPATH`` and the script checks
that ``quadest`` imports from there before running anything (one line and exit status 1 if not),
so an edit to ``src/`` reaches the regeneration without a reinstall.
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "results" / "manifest.yaml"


def read_manifest(path: Path = MANIFEST) -> dict[str, list[str]]:
    """Folder name (under ``results/``) -> the commands that make it, in order."""
    manifest = yaml.safe_load(path.read_text(encoding="utf-8"))
    for name, commands in manifest.items():
        if not commands or not all(isinstance(c, str) and c.strip() for c in commands):
            raise SystemExit(f"regenerate_results: {path.name}: '{name}' needs a list of commands")
    return manifest


def clone_environment(root: Path = ROOT) -> dict[str, str]:
    """The environment of the commands: this one with the clone's ``src/`` first on ``PYTHONPATH``,
    so that they run the clone's code whatever copy of quadest is installed (a non-editable
    install would otherwise serve the code of its build). Refuses with one line if ``quadest``
    still imports from elsewhere."""
    path = [str(root / "src"), *filter(None, [os.environ.get("PYTHONPATH")])]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path)}
    probe = [sys.executable, "-c", "import quadest; print(quadest.__file__)"]
    done = subprocess.run(probe, cwd=root, env=env, capture_output=True, text=True, check=False)
    found = Path(done.stdout.strip()).resolve() if done.returncode == 0 else None
    expected = (root / "src" / "quadest" / "__init__.py").resolve()
    if found != expected:
        raise SystemExit(f"regenerate_results: quadest imports from {found or done.stderr.strip()[-200:]}, not "
                         f"this clone's {expected}; run from the clone whose results you regenerate")  # fmt: skip
    return env


def run(command: str, env: dict[str, str] | None = None) -> bool:
    """Run one manifest command from the repository root with ``env`` (:func:`clone_environment`);
    ``quadest`` and ``python`` are those of this interpreter's environment."""
    argv = shlex.split(command)
    if argv[0] == "python":
        argv[0] = sys.executable
    elif argv[0] == "quadest":
        argv = [sys.executable, "-m", "quadest.app.cli", *argv[1:]]
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, check=False, env=env)
    print(f"  {time.perf_counter() - start:6.0f} s  exit {done.returncode}  {command}", flush=True)
    return done.returncode == 0


def regenerate(name: str, commands: list[str], env: dict[str, str] | None = None) -> bool:
    """Make ``results/name`` afresh; the old folder comes back if a command fails. The folder's
    ``README.md`` files, written by hand to explain a folder (no command makes them), are carried
    over into the new one."""
    folder = ROOT / "results" / name
    aside = folder.with_name(f".{name}.old")
    shutil.rmtree(aside, ignore_errors=True)
    if folder.exists():
        folder.rename(aside)
    ok = all(run(command, env) for command in commands)
    if ok:
        for readme in aside.rglob("README.md") if aside.exists() else ():
            target = folder / readme.relative_to(aside)
            if not target.exists():
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(readme, target)
        shutil.rmtree(aside, ignore_errors=True)
    elif aside.exists():
        shutil.rmtree(folder, ignore_errors=True)
        aside.rename(folder)
    return ok


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="+", metavar="NAME", help="only these folders of results/manifest.yaml")
    parser.add_argument("--list", action="store_true", help="list the folders and their commands, run nothing")
    args = parser.parse_args(argv)
    manifest = read_manifest()
    unknown = sorted(set(args.only or ()) - set(manifest))
    if unknown:
        print(f"regenerate_results: --only: unknown folder(s) {unknown}; allowed: {sorted(manifest)}", file=sys.stderr)
        return 2
    names = args.only or list(manifest)
    if args.list:
        for name in names:
            print(f"{name}:\n" + "".join(f"  {command}\n" for command in manifest[name]), end="")
        return 0
    env = clone_environment()
    failed = [name for name in names if not regenerate(name, manifest[name], env)]
    ok_ledger = all(
        subprocess.run([sys.executable, "-m", module], cwd=ROOT, check=False, env=env).returncode == 0
        for module in ("quadest.aggregate.reproductions", "quadest.aggregate.doc_numbers")
    )
    if failed:
        print(f"regenerate_results: failed: {', '.join(failed)} (their old folders are back)", file=sys.stderr)
    return int(bool(failed) or not ok_ledger)


if __name__ == "__main__":
    sys.exit(main())
