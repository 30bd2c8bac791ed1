"""Robust summaries of the error: the median and the 95th percentile of ``|error|`` over the steps
1..K, per run and row of the state table (filter states, derived errors, companion values).

RMSE weighs a short excursion by its square: one bad second can dominate a 20 s run. The median
says what the error typically is, the 95th percentile how large it gets apart from the worst 5 %
of the steps (Hyndman & Koehler, "Another look at measures of forecast accuracy", IJF 2006, on
scale-dependent measures; DAPPER reports error quantiles the same way). Quantiles need every step,
so this part keeps the error per step of the live runs: ``B·K·R`` floats (float32) while the
batch runs; only the two (B, R) columns reach the result. Quantiles by linear interpolation
(:func:`numpy.quantile`'s default); a run that diverged gets NaN, as its RMSE does.
"""

from __future__ import annotations

import numpy as np

from quadest.metrics.base import BatchStart, Column, Metric, StepView, state_rows
from quadest.models.base import FilterModel

QUANTILES = {"abs_error_median": 0.5, "abs_error_p95": 0.95}


def error_quantiles(errors: np.ndarray, axis: int = 1) -> dict[str, np.ndarray]:
    """The columns of :data:`QUANTILES` of ``|errors|`` along ``axis`` (the steps)."""
    magnitude = np.abs(np.asarray(errors, dtype=float))
    return {name: np.quantile(magnitude, q, axis=axis) for name, q in QUANTILES.items()}


class _Streams:
    def __init__(self, batch: BatchStart) -> None:
        R = len(state_rows(batch.model))
        self.errors = np.full((batch.runs, batch.time.size - 1, R), np.nan, dtype=np.float32)
        self.alive = np.ones(batch.runs, dtype=bool)

    def step(self, view: StepView) -> None:
        self.alive = view.alive.copy()
        self.errors[view.alive, view.k - 1] = view.rows[view.alive]

    def finish(self) -> dict[str, np.ndarray]:
        out = error_quantiles(self.errors, axis=1)
        for values in out.values():
            values[~self.alive] = np.nan
        return out


class ErrorQuantiles(Metric):
    name = "quantiles"

    def columns(self, model: FilterModel) -> tuple[Column, ...]:
        return (
            Column("abs_error_median", "state", "per-run median of |error| over steps 1..K", "median"),
            Column("abs_error_p95", "state", "per-run 95th percentile of |error| over steps 1..K"),
        )

    def start(self, batch: BatchStart) -> _Streams:
        return _Streams(batch)
