"""A job's size, estimated before any work: the memory its arrays need against what the machine has.

The estimate (:func:`job_bytes`) counts the float64 arrays that coexist while a simulated job runs,
with ``B`` runs, ``K + 1`` samples (:func:`~quadest.montecarlo.data.sample_count`), state
dimension ``n``, ``E`` estimators and ``P`` worker processes (:func:`~quadest.app.estimator_runs.resolve_workers`):

- the data, ``8 B (K + 1) 2n`` bytes: the truth (``n`` per sample) and at least as many values of
  measurements and inputs; each worker process holds its own copy, so ``(1 + P)`` copies with
  ``P > 1`` worker processes;
- each estimator's saved time series, ``8 S (K + 1) 3n`` bytes (``S`` = min(``output.saved_runs``,
  ``runs``): estimate, standard deviation and companions of the saved runs), kept for every estimator;
- each running estimator's state, ``8 B (2n + 1) n`` bytes (the sigma points of every run, the
  largest of a Gaussian filter's per-step arrays), in ``min(P, E)`` processes at once;
- each smoother's backward pass, ``8 · 2 K B n²`` bytes (the K transitions' gains and residuals,
  docs/smoothers.md; a particle smoother's clouds come on top).

It is a floor, not a peak (intermediate arrays and Python's own overhead come on top), so a job
refused by it cannot run. Above the memory the machine has available (``MemAvailable`` of
``/proc/meminfo``, else ``os.sysconf``'s available pages) the job is refused with one line naming
the keys to change; above :data:`WARN_FRACTION` of it, a warning. A flight-log replay is one run of
a log of known length and is not sized.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

from quadest.config.notices import warn
from quadest.errors import ConfigError
from quadest.montecarlo.data import sample_count

WARN_FRACTION = 0.5
"""Above this fraction of the available memory, a job is warned about (it may swap)."""

LONG_JOB_RUN_STEPS = 1_000_000
"""From this many run-steps (``runs × (K + 1)``) on, a job prints progress lines to stderr."""

_GIB = 2**30


def job_bytes(
    runs: int, steps: int, n: int, estimators: int, processes: int, saved_runs: int, smoothers: int = 0
) -> int:
    """The floor of the memory a simulated job needs, in bytes (module docstring); ``steps`` is K + 1."""
    data = 8 * runs * steps * 2 * n
    copies = 1 + processes if processes > 1 else 1
    saved = estimators * 8 * min(saved_runs, runs) * steps * 3 * n
    state = min(processes, estimators) * 8 * runs * (2 * n + 1) * n
    backward = smoothers * 8 * 2 * (steps - 1) * runs * n * n
    return copies * data + saved + state + backward


def available_memory() -> int | None:
    """Bytes of memory available to a new job: ``MemAvailable`` (Linux), else the available
    physical pages (``os.sysconf``); ``None`` where neither is known."""
    meminfo = Path("/proc/meminfo")
    if meminfo.is_file():
        for line in meminfo.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_size(
    runs: int,
    duration: float,
    sample_period: float,
    n: int,
    estimators: int,
    processes: int,
    saved_runs: int,
    smoothers: int = 0,
) -> int:
    """Refuse (:class:`ConfigError`) a job whose :func:`job_bytes` exceed the available memory;
    warn on stderr above :data:`WARN_FRACTION` of it. Returns the estimate in bytes."""
    steps = sample_count(duration, sample_period) + 1
    need = job_bytes(runs, steps, n, estimators, processes, saved_runs, smoothers)
    have = available_memory()
    if have is None:
        return need
    what = (
        f"about {need / _GIB:.3g} GiB for {runs} runs x {steps} samples (duration={duration:g} s, "
        f"sample_period={sample_period:g} s) of a {n}-state model, {estimators} estimator(s) ({smoothers} with a "
        f"smoother) in {processes} process(es); this machine has {have / _GIB:.3g} GiB available"
    )
    if need > have:
        raise ConfigError("runs", runs, f"the job needs {what}; lower runs or duration, raise sample_period, or "
                          "lower workers or output.saved_runs (docs/usage.md: sizing)")  # fmt: skip
    if need > WARN_FRACTION * have:
        warn(f"the job needs {what}; it may swap (docs/usage.md: sizing)")
    return need


def is_long(runs: int, duration: float, sample_period: float) -> bool:
    """Whether a job is long enough to print progress lines (:data:`LONG_JOB_RUN_STEPS`)."""
    return runs * (sample_count(duration, sample_period) + 1) >= LONG_JOB_RUN_STEPS


def duration_problem(duration: float, sample_period: float) -> str | None:
    """Why ``duration`` cannot be sampled (not finite, or more samples than an index holds)."""
    if not math.isfinite(duration):
        return f"{duration} is not a finite number; must be a finite number of seconds"
    if duration / sample_period >= sys.maxsize:
        return f"{duration / sample_period:.3g} samples at sample_period={sample_period:g} is more than can be indexed"
    return None
