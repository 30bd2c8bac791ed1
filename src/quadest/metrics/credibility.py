"""Credibility of the covariance a filter reports, beside its consistency: the non-credibility
index and the inclination index (Li, Zhao & Jilkov, "Estimator's credibility and its measures",
IFAC World Congress 2002; Li & Zhao, "Measuring estimator's credibility: noncredibility index",
FUSION 2006).

At step k, over the M runs alive with a NEES, the filter's own normalised error
``ε_i = x̃_iᵀ P_i⁻¹ x̃_i`` (its NEES) is set against the error normalised by the actual mean-square
error matrix ``Σ = (1/M) Σ_i x̃_i x̃_iᵀ``: ``ε*_i = x̃_iᵀ Σ⁻¹ x̃_i``, and ``ρ_i = ε_i / ε*_i``. Then

- inclination index ``(10/M) Σ_i log10 ρ_i`` (dB): > 0 the filter is optimistic (it reports a
  covariance smaller than its actual MSE), < 0 pessimistic, 0 credible;
- non-credibility index (NCI) ``(10/M) Σ_i |log10 ρ_i|`` (dB): how far from credible, in either
  direction (0 for a credible filter).

(The 2002 paper's first form of the NCI is the signed mean, here the inclination index.) The
columns are the averages of the per-step indices over the steps 1..K where they are defined: Σ
needs more runs than error states (M > n_err) and must be positive definite; with fewer runs the
column is NaN. Trust them from some tens of runs on: Σ is itself estimated from the M runs.
"""

from __future__ import annotations

import numpy as np

from quadest.metrics.base import BatchStart, Column, Metric, StepView
from quadest.models.base import FilterModel


def credibility_terms(error: np.ndarray, nees: np.ndarray) -> np.ndarray:
    """``10 log10 ρ_i`` (M,) of the runs ``error`` (M, n) with their NEES (M,); empty when Σ is
    not defined (M ≤ n, or not positive definite)."""
    M, n = error.shape
    if M <= n:
        return np.empty(0)
    try:
        L = np.linalg.cholesky(error.T @ error / M)
    except np.linalg.LinAlgError:
        return np.empty(0)
    actual = np.sum(np.linalg.solve(L, error.T) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = 10.0 * np.log10(nees / actual)
    return terms[np.isfinite(terms)]


class _Streams:
    def __init__(self, steps: int) -> None:
        self.nci_t, self.inclination_t = np.full(steps + 1, np.nan), np.full(steps + 1, np.nan)

    def step(self, view: StepView) -> None:
        use = view.alive & np.isfinite(view.nees) & np.isfinite(view.error).all(axis=-1)
        terms = credibility_terms(view.error[use], view.nees[use])
        if terms.size:
            self.inclination_t[view.k], self.nci_t[view.k] = terms.mean(), np.abs(terms).mean()

    def finish(self) -> dict[str, float]:
        defined = np.isfinite(self.nci_t)
        if not defined.any():
            return {"nci": np.nan, "inclination": np.nan}
        return {"nci": float(self.nci_t[defined].mean()), "inclination": float(self.inclination_t[defined].mean())}


class Credibility(Metric):
    name = "credibility"

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        return (
            Column("nci", "estimator", "non-credibility index (dB, 0 = credible), time average over steps 1..K"),
            Column("inclination", "estimator", "inclination index (dB, > 0 optimistic, < 0 pessimistic)"),
        )

    def start(self, batch: BatchStart) -> _Streams:
        return _Streams(batch.time.size - 1)
