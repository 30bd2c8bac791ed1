"""The built-in metrics every job reports: RMSE, divergence, NEES, NIS, time per step and the
estimators' own diagnostics.

Their sums are the runner's core (:class:`~quadest.montecarlo.results.EstimatorResult`: the
divergence flags need the errors and the NEES at every step anyway), so these parts stream
nothing: they declare the columns and read them from the result.

- RMSE: per run and row, ``sqrt(mean over steps 1..K of error²)`` (the convention of
  :mod:`quadest.evaluation.metrics`).
- NEES ``x̃ᵀP⁻¹x̃`` (n_err dof) and NIS ``νᵀS⁻¹ν`` (m dof): per-run time averages, and per
  estimator the share of steps whose run average lies in the two-sided 95 % χ² band
  (Bar-Shalom, Li & Kirubarajan 2001, §5.4.2; :mod:`quadest.metrics.consistency`).
"""

from __future__ import annotations

import numpy as np

from quadest.metrics.base import Column, Metric
from quadest.metrics.consistency import fraction_inside
from quadest.models.base import FilterModel
from quadest.montecarlo.results import EstimatorResult


class RMSE(Metric):
    name = "rmse"

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        return (Column("rmse", "state", "per-run RMSE over steps 1..K; empty if the run diverged"),)

    def values(self, result: EstimatorResult, model: FilterModel) -> dict[str, np.ndarray]:
        return {"rmse": np.concatenate([result.rmse, result.derived_rmse, result.companion_rmse], axis=-1)}


class Divergence(Metric):
    name = "divergence"
    needs_truth = False

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        return (
            Column("diverged", "run", "whether the run was flagged"),
            Column("diverged_step", "run", "the step it was flagged at (-1: never)"),
            Column("failure_reason", "run", "why it was flagged"),
        )

    def values(self, result: EstimatorResult, model: FilterModel) -> dict[str, np.ndarray]:
        B = result.diverged.shape[0]
        return {
            "diverged": result.diverged,
            "diverged_step": result.diverged_step,
            "failure_reason": [result.reasons.get(i, "") for i in range(B)],
        }

    def overview(self, result: EstimatorResult, model: FilterModel) -> dict[str, float]:
        return {"diverged": int(result.diverged.sum()), "runs": int(result.diverged.size)}


class NEES(Metric):
    name = "nees"

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        return (Column("mean_nees", "run", "per-run time average of the NEES (n_err dof)"),)

    def values(self, result: EstimatorResult, model: FilterModel) -> dict[str, np.ndarray]:
        return {"mean_nees": result.mean_nees}

    def overview(self, result: EstimatorResult, model: FilterModel) -> dict[str, float]:
        n, alive = model.n_err, (~result.diverged).any()
        return {
            "mean_nees": float(np.nanmean(result.mean_nees)) if alive else np.nan,
            "nees_dof": n,
            "nees_in_band": fraction_inside(result.nees_mean_t, n, result.alive_t),
        }


class NIS(Metric):
    name = "nis"
    needs_truth = False

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        return (Column("mean_nis", "run", "per-run time average of the primary measurement's NIS (m dof)"),)

    def values(self, result: EstimatorResult, model: FilterModel) -> dict[str, np.ndarray]:
        """NaN for a model without a primary measurement (m = 0: its sensors' NIS are per group)."""
        return {"mean_nis": result.mean_nis if model.m else np.full(result.mean_nis.shape, np.nan)}

    def overview(self, result: EstimatorResult, model: FilterModel) -> dict[str, float]:
        m, alive = model.m, (~result.diverged).any()
        if not m:
            return {"mean_nis": np.nan, "nis_dof": 0, "nis_in_band": np.nan}
        return {
            "mean_nis": float(np.nanmean(result.mean_nis)) if alive else np.nan,
            "nis_dof": m,
            "nis_in_band": fraction_inside(result.nis_mean_t, m, result.alive_t),
        }


class StepTime(Metric):
    name = "step_time"
    needs_truth = False

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        return (Column("step_time_us", "estimator", "wall time of predict + update per step per run"),)

    def values(self, result: EstimatorResult, model: FilterModel) -> dict[str, float]:
        return {"step_time_us": result.step_time_us}


class Diagnostics(Metric):
    """The estimator's own per-run diagnostics (:meth:`quadest.estimators.base.Estimator.diagnostics`):
    their names are the estimator's, so they are read from the result, not declared here."""

    name = "diagnostics"
    needs_truth = False

    def values(self, result: EstimatorResult, model: FilterModel) -> dict[str, np.ndarray]:
        return dict(result.diagnostics)

    def overview(self, result: EstimatorResult, model: FilterModel) -> dict[str, float]:
        return {}


BUILT_IN = (RMSE(), Divergence(), NEES(), NIS(), StepTime(), Diagnostics())
"""In the order of their columns in ``metrics.csv``."""
