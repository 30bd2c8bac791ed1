"""What a metric is: a part that sees every step of a batch and gives columns (docs/metrics.md).

A metric (:class:`Metric`) declares its :class:`Column` s and, if it needs more than what the
runner keeps for every estimator (the RMSE, NEES and NIS sums of
:class:`~quadest.montecarlo.results.EstimatorResult`), a streaming :class:`Accumulator`:
:meth:`Metric.start` is called once per estimator and batch with the :class:`BatchStart`,
:meth:`Accumulator.step` once per step 1..K with a :class:`StepView` (the step's errors, the
covariance factor, NEES, NIS, the innovations and the mask of the runs still alive), and
:meth:`Accumulator.finish` once at the end; what it returns is kept in
``EstimatorResult.metric_values`` (cached with the result). The tables then read the columns
through :meth:`Metric.values` (metrics.csv) and :meth:`Metric.overview` (the per-estimator
overview, ``summary.json``, the sweep's tables).

A column is given per run and row of the state table (``per="state"``: an array (B, R), the R
rows being the filter states, the derived errors and the companion values, in that order, as in
``metrics.csv``), per run (``per="run"``: (B,)) or once per estimator (``per="estimator"``: a
number). ``aggregate`` says how ``rmse_summary.csv`` (per-state columns) and the overview
(per-run columns) reduce it over the runs that did not diverge.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from quadest.metrics.settings import MetricsConf
from quadest.models.base import FilterModel
from quadest.montecarlo.results import EstimatorResult

Per = Literal["state", "run", "estimator"]
AGGREGATES = {"mean": np.mean, "median": np.median}
"""How a per-state or per-run column is reduced over the runs that did not diverge."""


@dataclass(frozen=True)
class Column:
    """A column of ``metrics.csv``: its name, what it is given for (:data:`Per`), how it is reduced
    over the live runs (a key of :data:`AGGREGATES`) and one line on what it means (docs/outputs.md)."""

    name: str
    per: Per
    meaning: str
    aggregate: str = "mean"


@dataclass(frozen=True)
class BatchStart:
    """What a metric knows when a batch starts: the filter model, the sample times (K+1,) and the
    number of runs B."""

    model: FilterModel
    time: np.ndarray
    runs: int


@dataclass(frozen=True)
class StepView:
    """One step k ≥ 1 of a batch, after the updates: ``error`` (B, n_err) the estimate ⊟ truth,
    ``derived`` (B, d) the model's derived errors, ``companion`` (B, nc) the companion values'
    errors, ``factor`` (B, n_err, n_err) the lower factor of each run's covariance (NaN where it is
    not positive definite), ``nees`` and ``nis`` (B,) (NaN where not available), ``alive`` (B,)
    the runs that have not diverged up to and including this step, and ``innovations`` the
    innovation ν (B, m) and the lower factor of its covariance S (B, m, m) of each measurement
    that updated the filter at this step (key ``None``: the primary measurement; a further
    sensor's name), as the estimator gave them after that update (NaN for a run without one);
    empty for an estimator without innovations (particle filters)."""

    k: int
    error: np.ndarray
    derived: np.ndarray
    companion: np.ndarray
    factor: np.ndarray
    nees: np.ndarray
    nis: np.ndarray
    alive: np.ndarray
    innovations: Mapping[str | None, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    @property
    def rows(self) -> np.ndarray:
        """(B, R) the errors of every row of the state table: filter, derived, companion."""
        return np.concatenate([self.error, self.derived, self.companion], axis=-1)


class Accumulator(Protocol):
    """The streaming state of one metric over one estimator's batch."""

    def step(self, view: StepView) -> None: ...

    def finish(self) -> Mapping[str, np.ndarray]: ...


class Metric:
    """A metric part. Subclasses set ``name`` and override :meth:`columns` and, for a streaming
    metric, :meth:`start`; the default :meth:`values` reads ``result.metric_values``, the default
    :meth:`overview` reduces each per-run column over the live runs (NaN when none is left) and
    passes per-estimator columns through; :meth:`summary` is for columns of ``rmse_summary.csv`` a
    metric computes itself."""

    name: str = ""
    needs_truth: bool = True
    """Whether its columns need the true state (a flight log has none: they are left empty there)."""

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        """The columns this metric adds to ``metrics.csv`` on ``model`` (may be none)."""
        return ()

    def start(self, batch: BatchStart) -> Accumulator | None:
        """A fresh accumulator for one estimator's batch; ``None`` if nothing is streamed."""
        return None

    def values(self, result: EstimatorResult, model: FilterModel) -> dict[str, np.ndarray | float]:
        """Each column's values for ``result``: (B, R), (B,) or a number by its ``per``; NaN for a
        column the result does not hold (an estimator that could not run, a result from an older
        version)."""
        B, R = result.diverged.shape[0], len(state_rows(model))
        empty: dict[Per, object] = {"state": np.full((B, R), np.nan), "run": np.full(B, np.nan), "estimator": np.nan}
        return {c.name: result.metric_values.get(c.name, empty[c.per]) for c in self.columns(model)}

    def overview(self, result: EstimatorResult, model: FilterModel) -> dict[str, float]:
        """Per-estimator entries: per-run columns reduced over the live runs, per-estimator columns
        as they are."""
        values, live = self.values(result, model), ~result.diverged
        out = {}
        for c in self.columns(model):
            if c.per == "run":
                kept = np.asarray(values[c.name])[live]
                kept = kept[np.isfinite(kept)]
                out[c.name] = float(AGGREGATES[c.aggregate](kept)) if kept.size else float("nan")
            elif c.per == "estimator":
                out[c.name] = float(values[c.name])
        return out

    def summary(self, result: EstimatorResult, model: FilterModel, settings: MetricsConf) -> dict[str, np.ndarray]:
        """Columns of ``rmse_summary.csv`` that this metric computes itself from what it kept, one value
        per row of the state table (R,), named by :meth:`summary_columns`. (Per-state columns are
        reduced over the live runs by the table builder, :func:`quadest.evaluation.metrics.metric_summary`.)"""
        return {}

    def summary_columns(self, model: FilterModel) -> tuple[str, ...]:
        """The names :meth:`summary` gives."""
        return ()


def state_rows(model: FilterModel) -> list[tuple[str, str, str]]:
    """The rows of the state table, (quantity, state, unit): the filter states, the derived errors,
    the companion values."""
    blocks = (
        ("filter", model.error_names, model.error_units),
        ("derived", model.derived_error_names, model.derived_error_units),
        ("companion", model.companion_names, model.companion_units),
    )
    return [(q, s, u) for q, names, units in blocks for s, u in zip(names, units, strict=True)]
