"""Every benchmark script runs to its end in its quick mode (``--quick``: toy sizes, no timing
asserted), so that a script that breaks fails the suite instead of rotting unseen.

The scripts are found in ``benchmarks/``: every file with a ``__main__`` block is run with
``--quick``, except the scripts that run in a separate environment (a library that must never be
a quadest dependency); those are run by their driver, given that environment's Python, and skipped
with the reason when it is absent. A new script is covered without editing this file; a new
separate-environment script must be added to ``SEPARATE`` (run directly, its imports fail).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

SEPARATE = {
    # script run in another environment: (its driver, the driver's option, the variable naming that Python)
    "particles_ungm.py": ("bench_particle.py", "--particles-python", "QUADEST_PARTICLES_PYTHON"),
    "dynamax_filters.py": ("bench_dynamax.py", "--dynamax-python", "QUADEST_DYNAMAX_PYTHON"),
}


def scripts() -> list[str]:
    """The benchmark scripts: files of ``benchmarks/`` with a ``__main__`` block."""
    return sorted(p.name for p in BENCHMARKS.glob("*.py") if '__name__ == "__main__"' in p.read_text())


def run_quick(script: str, *extra: str) -> subprocess.CompletedProcess:
    """``python benchmarks/SCRIPT --quick EXTRA`` with no separate environment unless given."""
    env = {k: v for k, v in os.environ.items() if k not in {var for _, _, var in SEPARATE.values()}}
    return subprocess.run(
        [sys.executable, str(BENCHMARKS / script), "--quick", *extra],
        cwd=BENCHMARKS,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )


def test_the_scripts_are_found():
    """Discovery finds the drivers and the separate-environment scripts (a broken glob or marker
    would otherwise make the tests below pass by running nothing)."""
    found = scripts()
    assert {"bench_srukf.py", "bench_particle.py", "bench_baselines.py", "bench_dynamax.py"} <= set(found)
    assert set(SEPARATE) <= set(found)
    for driver, option, _ in SEPARATE.values():
        assert driver in found and option in (BENCHMARKS / driver).read_text()


@pytest.mark.parametrize("script", [s for s in scripts() if s not in SEPARATE])
@pytest.mark.slow
def test_quick_mode_runs(script):
    done = run_quick(script)
    assert done.returncode == 0, f"{script} --quick failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"


@pytest.mark.parametrize("script", sorted(SEPARATE))
def test_separate_environment_script_runs(script):
    """The driver's quick mode with the separate environment's Python, when it is installed
    (the variable names it; docs/benchmarks.md says how to create it)."""
    driver, option, variable = SEPARATE[script]
    python = os.environ.get(variable)
    if not python or not Path(python).exists():
        pytest.skip(f"{script} needs its own environment: set {variable} to its Python (docs/benchmarks.md)")
    done = run_quick(driver, option, python)
    assert done.returncode == 0, f"{driver} --quick {option} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    assert "skipped" not in done.stdout
