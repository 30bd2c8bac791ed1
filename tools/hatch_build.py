"""Hatchling build hook: record the commit a wheel or an sdist is built from.

A non-editable install (``pip install .``) copies the package into site-packages, away from the
git checkout, so at run time :mod:`quadest.app.provenance` cannot ask git which commit made it.
This hook asks git at build time and puts ``quadest/_build_info.json`` into the wheel
(``src/quadest/_build_info.json`` into an sdist, so that a wheel built from the sdist carries it
too): the commit, whether the tracked code (``src/``, ``conf/``, ``experiments/``) differed from
it, and when the build ran. An editable install records nothing: it runs the checkout itself,
which git describes at run time. Outside a git checkout nothing is written, and the summary says
the commit is unknown (docs/outputs.md, "Provenance").
"""

from __future__ import annotations

import json
import subprocess
import tempfile
import time
from pathlib import Path

from hatchling.builders.hooks.plugin.interface import BuildHookInterface

BUILD_INFO = "_build_info.json"


def _git(root: str, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


class BuildInfoHook(BuildHookInterface):
    """Writes :data:`BUILD_INFO` into the built package (module docstring)."""

    PLUGIN_NAME = "custom"

    def initialize(self, version: str, build_data: dict) -> None:
        if version == "editable":
            return
        commit = _git(self.root, "rev-parse", "HEAD")
        if commit is None:
            return
        status = _git(self.root, "status", "--porcelain", "--untracked-files=no", "--", "src", "conf", "experiments")
        info = {"commit": commit, "commit_dirty": None if status is None else bool(status),
                "built": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}  # fmt: skip
        self._folder = tempfile.TemporaryDirectory(prefix="quadest-build-info-")
        path = Path(self._folder.name) / BUILD_INFO
        path.write_text(json.dumps(info, indent=2) + "\n")
        inside = "src/quadest" if self.target_name == "sdist" else "quadest"
        build_data["force_include"][str(path)] = f"{inside}/{BUILD_INFO}"

    def finalize(self, version: str, build_data: dict, artifact_path: str) -> None:
        folder = getattr(self, "_folder", None)
        if folder is not None:
            folder.cleanup()
