"""Confidence intervals over Monte Carlo runs: of a mean, and of a ratio of two paired means.

Both are Student-t intervals, so a 95 % interval of a normal mean covers 95 % at any run count
(the percentile bootstrap these replace covers ``P(|t_{n−1}| ≤ z √((n−1)/n))``: 0.94 at 30 runs,
0.85 at 5, and no interval inside the range of the data can cover more than ``1 − 2^{1−n}`` of a
symmetric distribution's mean, 0.94 at 5 runs).

- The mean of ``x`` over ``n`` runs: ``x̄ ± t_{n−1, 1−α/2} · s / √n`` (Student 1908).
- The ratio ``r = ā / b̄`` of the means of paired per-run values ``a_i, b_i`` (the same runs:
  common random numbers), two ways. Both pair each run's numerator with its own denominator, so
  a correlated ``a`` and ``b`` (a filter's error and its reference's on the same run) give a
  narrow interval, as they should.

  *Fieller's interval* (Fieller 1954, *J. R. Statist. Soc. B* 16, 175–185), the 95 % tables':
  the ratios ``ρ`` that a paired t-test of the residuals ``a_i − ρ b_i`` does not reject,
  ``(ā − ρ b̄)² ≤ (t²/n) · s²(a − ρ b)``, a quadratic inequality in ``ρ``. It is exact whenever
  those residuals are normal, at any run count; when ``b̄`` itself is not significantly non-zero
  (``b̄² ≤ (t²/n) s_b²``) the set is unbounded and both ends are NaN.

  *The delta-method interval* of the ratio estimator (Cochran 1977, *Sampling Techniques*, 3rd
  ed., ch. 6), from the residuals ``e_i = a_i − r̂ b_i``, ``r̂ ± t_{n−1, 1−α/2} · s_e / (√n · |b̄|)``:
  symmetric, a large-sample approximation (it covers 0.93 at 5 runs of runs differing tenfold in
  scale, 0.94 at 20), used by α-spending's batches of 50 runs and more
  (:mod:`quadest.evaluation.sequential`).

Arrays are (runs, comparisons); with fewer than two runs every result is NaN. ``miss`` is the
probability the interval misses (0.05 for a 95 % interval); α-spending passes tiny ones
(:mod:`quadest.evaluation.sequential`), which is why it is not written as ``1 − confidence``.
"""

from __future__ import annotations

import numpy as np
from scipy import stats


def t_quantile(n: int, miss: float) -> float:
    """Student's two-sided quantile ``t_{n−1, 1−α/2}`` of an interval that misses with
    probability ``miss = α`` (NaN below 2 runs)."""
    return float(stats.t.isf(miss / 2.0, n - 1)) if n >= 2 else np.nan


def mean_and_half_width(x: np.ndarray, miss: float) -> tuple[np.ndarray, np.ndarray]:
    """The mean over runs (axis 0) and the half-width of its Student-t interval."""
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if n < 2:
        nan = np.full(x.shape[1:], np.nan)
        return nan, nan.copy()
    return x.mean(axis=0), t_quantile(n, miss) * x.std(axis=0, ddof=1) / np.sqrt(n)


def ratio_and_half_width(a: np.ndarray, b: np.ndarray, miss: float) -> tuple[np.ndarray, np.ndarray]:
    """``r̂ = ā / b̄`` over paired runs (axis 0) and the half-width of its delta-method interval
    (module docstring); a mean ``b̄`` of 0 gives an infinite or NaN ratio."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = a.shape[0]
    if n < 2:
        nan = np.full(a.shape[1:], np.nan)
        return nan, nan.copy()
    mean_a, mean_b = a.mean(axis=0), b.mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = mean_a / mean_b
        residual = a - ratio * b
        half = t_quantile(n, miss) * residual.std(axis=0, ddof=1) / (np.sqrt(n) * np.abs(mean_b))
    return ratio, half


def fieller_interval(a: np.ndarray, b: np.ndarray, miss: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``r̂ = ā / b̄`` over paired runs (axis 0) and the ends of Fieller's interval (module
    docstring): NaN ends where the set is unbounded or with fewer than two runs."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = a.shape[0]
    nan = np.full(a.shape[1:], np.nan)
    if n < 2:
        return nan, nan.copy(), nan.copy()
    mean_a, mean_b = a.mean(axis=0), b.mean(axis=0)
    da, db = a - mean_a, b - mean_b
    s_aa, s_bb, s_ab = ((x * y).sum(axis=0) / (n - 1) for x, y in ((da, da), (db, db), (da, db)))
    q = t_quantile(n, miss) ** 2 / n
    # (ā − ρ b̄)² − q (s_aa − 2ρ s_ab + ρ² s_bb) ≤ 0  ⇔  c2 ρ² − 2 c1 ρ + c0 ≤ 0
    c2, c1, c0 = mean_b**2 - q * s_bb, mean_a * mean_b - q * s_ab, mean_a**2 - q * s_aa
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = mean_a / mean_b
        root = np.sqrt(np.maximum(c1**2 - c0 * c2, 0.0))
        low, high = (c1 - root) / c2, (c1 + root) / c2
    bounded = c2 > 0
    return ratio, np.where(bounded, low, np.nan), np.where(bounded, high, np.nan)
