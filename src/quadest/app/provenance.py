"""What made a job's numbers, for its ``summary.json``: the commit, whether the tree was dirty,
and the code version of the result cache."""

from __future__ import annotations

import subprocess
from pathlib import Path

from quadest.cache.keys import code_version


def _git(*args: str) -> str | None:
    """``git ARGS`` in the package's folder: its output, or ``None`` outside a git checkout."""
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).parent, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def git_commit() -> str:
    """The commit of the source tree, or ``"unknown"`` outside a git checkout."""
    return _git("rev-parse", "HEAD") or "unknown"


def provenance() -> dict:
    """What made a job's numbers, for its ``summary.json``: ``commit`` (HEAD of the checkout),
    ``commit_dirty`` (whether the tracked code differed from that commit: the package source, the
    configs and the sweep files, ``src/``, ``conf/``, ``experiments/``; results being rewritten do
    not count; ``None`` outside git) and ``code_version`` (the digest of the package source and
    the numeric libraries' versions, :func:`quadest.cache.keys.code_version`, which names the code
    in a dirty tree and outside git too)."""
    status = _git("status", "--porcelain", "--untracked-files=no", "--", ":/src", ":/conf", ":/experiments")
    return {"commit": git_commit(), "commit_dirty": None if status is None else bool(status),
            "code_version": code_version()}  # fmt: skip
