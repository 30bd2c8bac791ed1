"""What made a job's numbers, for its ``summary.json``: the commit, whether the code differed from
it, where that was learnt, and the code version of the result cache.

Two ways to learn the commit, whichever install ran the job (docs/outputs.md, "Provenance"):

- **git, at run time**: the package runs from a git checkout (an editable install, or a clone's
  ``src/`` on ``PYTHONPATH``): ``git`` in the package's folder, the package being tracked there;
- **the build record**: a non-editable install (``pip install .``) carries
  ``quadest/_build_info.json``, written by the build hook ``tools/hatch_build.py`` from the tree it
  was built from; edits to that tree after the build are not seen, and the summary says so.

Outside both, the commit is ``"unknown"``; ``code_version`` still names the code that ran.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from quadest.cache.keys import code_version

PACKAGE = Path(__file__).resolve().parents[1]
BUILD_INFO = PACKAGE / "_build_info.json"
BUILD_NOTE = ("recorded when this non-editable install was built (tools/hatch_build.py); edits to the source tree "
              "after the build are not seen: code_version names the code that ran")  # fmt: skip
UNKNOWN_NOTE = ("neither a git checkout nor a build record (an install built outside git): the commit is unknown; "
                "code_version names the code that ran")  # fmt: skip


def _git(*args: str) -> str | None:
    """``git ARGS`` in the package's folder: its output, or ``None`` outside a git checkout."""
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).parent, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def _checkout() -> bool:
    """Whether this package is a tracked part of a git checkout (not a copy that merely sits
    inside one, as a virtual environment's site-packages can)."""
    return _git("ls-files", "--error-unmatch", Path(__file__).name) is not None


def git_commit() -> str:
    """The commit of the source tree, or ``"unknown"`` outside a git checkout."""
    return (_git("rev-parse", "HEAD") if _checkout() else None) or "unknown"


def build_record() -> dict | None:
    """The build hook's record of a non-editable install, or ``None``."""
    try:
        return json.loads(BUILD_INFO.read_text())
    except (OSError, ValueError):
        return None


def provenance() -> dict:
    """What made a job's numbers, for its ``summary.json``: ``commit``, ``commit_dirty`` (whether
    the tracked code differed from that commit: the package source, the configs and the sweep
    files, ``src/``, ``conf/``, ``experiments/``; results being rewritten do not count; ``None``
    when unknown), ``commit_source`` (``"git"``, ``"build"`` or ``None``, module docstring) with
    a ``provenance_note`` when it is not git, and ``code_version`` (the digest of the package
    source and the numeric libraries' versions, :func:`quadest.cache.keys.code_version`)."""
    if _checkout():
        status = _git("status", "--porcelain", "--untracked-files=no", "--", ":/src", ":/conf", ":/experiments")
        return {"commit": git_commit(), "commit_dirty": None if status is None else bool(status),
                "commit_source": "git", "code_version": code_version()}  # fmt: skip
    record = build_record()
    if record is not None and record.get("commit"):
        return {"commit": record["commit"], "commit_dirty": record.get("commit_dirty"), "commit_source": "build",
                "provenance_note": BUILD_NOTE, "code_version": code_version()}  # fmt: skip
    return {"commit": "unknown", "commit_dirty": None, "commit_source": None, "provenance_note": UNKNOWN_NOTE,
            "code_version": code_version()}  # fmt: skip
