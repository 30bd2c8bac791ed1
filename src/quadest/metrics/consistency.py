"""χ² consistency of a filter over Monte Carlo runs (Bar-Shalom, Li & Kirubarajan 2001, §5.4:
the NEES and NIS tests; docs/verification.md).

NEES ``x̃ᵀP⁻¹x̃`` is χ²(n) and NIS ``νᵀS⁻¹ν`` is χ²(m) when the filter is consistent. Averaged
over N runs, ``N·ε̄ ~ χ²(N·d)``, so the two-sided 95 % band of the run-average is
``[χ²(Nd, 0.025)/N, χ²(Nd, 0.975)/N]`` (n = 2, N = 50: [1.48, 2.59]; n = 6, N = 50: [5.08, 7.00]).
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2


def chi2_band(dof: int, runs: np.ndarray | int, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper ends of the two-sided ``level`` band of a run-averaged χ²(dof) statistic
    with ``runs`` runs (an array gives one band per time step; 0 runs give NaN)."""
    runs = np.asarray(runs, dtype=float)
    tail = (1.0 - level) / 2.0
    with np.errstate(invalid="ignore", divide="ignore"):
        safe = np.where(runs > 0, runs, np.nan)
        return chi2.ppf(tail, safe * dof) / safe, chi2.ppf(1.0 - tail, safe * dof) / safe


MIN_SHARE_OF_STEPS = 0.5
"""A band share is reported only when the statistic was available on at least this share of the
steps 1..K: over fewer (every run diverged early) it would describe a few steps of a few runs, and
"100 % in band" from one surviving step reads as a consistent filter. Otherwise NaN ("n/a")."""


def fraction_inside(average_t: np.ndarray, dof: int, alive_t: np.ndarray, scheduled: np.ndarray | None = None) -> float:
    """Fraction of the time steps 1..K (with at least one live run) whose run-averaged statistic
    lies inside its 95 % band; NaN when the statistic is not available, or available on fewer than
    :data:`MIN_SHARE_OF_STEPS` of the steps 1..K. ``scheduled`` (K+1,) restricts both to the steps
    at which the statistic exists at all (a sensor's samples, for its NIS)."""
    lo, hi = chi2_band(dof, alive_t)
    expected = np.arange(average_t.size) > 0
    if scheduled is not None:
        expected &= scheduled
    steps = expected & (alive_t > 0) & np.isfinite(average_t)
    if steps.sum() < MIN_SHARE_OF_STEPS * expected.sum() or not steps.any():
        return float("nan")
    return float(np.mean((average_t[steps] >= lo[steps]) & (average_t[steps] <= hi[steps])))
