"""The code base stays ruff-clean, lint and format (ruff is in the test extras)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(importlib.util.find_spec("ruff") is None, reason="ruff is not installed (pip install '.[test]')")
def test_ruff_is_clean():
    command = [sys.executable, "-m", "ruff", "check", "src", "tests", "benchmarks", "examples"]
    proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


@pytest.mark.skipif(importlib.util.find_spec("ruff") is None, reason="ruff is not installed (pip install '.[test]')")
def test_ruff_format_is_clean():
    """The Python sources keep ruff's formatting (``ruff format`` fixes them; ``# fmt: skip`` marks
    the few hand-aligned tables)."""
    command = [sys.executable, "-m", "ruff", "format", "--check", "src", "tests", "benchmarks", "examples", "tools"]
    proc = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
