"""The transient apart from the steady state: the RMSE over the first steps, over the last steps,
and the time it takes a state's error to settle (the windows: the ``metrics`` config node,
:class:`quadest.metrics.settings.MetricsConf`).

Per estimator and row of the state table, pooled over the runs alive at each step (as
``pooled_rmse`` is): ``transient_rmse`` over the first ``metrics.transient`` fraction of the
steps 1..K, ``steady_rmse`` over the last ``metrics.steady`` fraction, and ``time_to_converge_s``,
the first time after which the RMS over the runs stays below ``metrics.settle_factor`` times the
steady-state RMSE (:func:`convergence_time`: a settling time in the sense of a step response's,
with the band set by the filter's own steady state; NaN where the RMS does not end inside it).
A filter's mean RMSE over a run mixes how fast it recovers from its initial error with how well
it tracks afterwards; these columns keep the two apart (the transient and steady-state errors of
an estimator's evaluation, e.g. Bar-Shalom, Li & Kirubarajan 2001, §5.4).
"""

from __future__ import annotations

import numpy as np

from quadest.metrics.base import BatchStart, Metric, StepView, state_rows
from quadest.metrics.settings import MetricsConf
from quadest.models.base import FilterModel
from quadest.montecarlo.results import EstimatorResult

SUMMARY = ("transient_rmse", "steady_rmse", "time_to_converge_s")


def convergence_time(time: np.ndarray, rms: np.ndarray, threshold: float) -> float:
    """The first time ``time[k]`` from which ``rms[k:]`` stays below ``threshold``: ``time[0]``
    if it never exceeds it, NaN if its last value does not lie below (NaN values count as not
    below: no run alive)."""
    below = rms < threshold
    if not below[-1]:
        return float("nan")
    above = np.flatnonzero(~below)
    return float(time[above[-1] + 1] if above.size else time[0])


def window_rmse(sq_t: np.ndarray, alive_t: np.ndarray, window: slice) -> np.ndarray:
    """(R,) ``sqrt`` of the squared errors summed over the window's steps and live runs divided by
    their count; NaN if no run was alive in it."""
    count = alive_t[window].sum()
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(sq_t[window].sum(axis=0) / count) if count else np.full(sq_t.shape[1], np.nan)


def windowed(time: np.ndarray, sq_t: np.ndarray, alive_t: np.ndarray, settings: MetricsConf) -> dict[str, np.ndarray]:
    """The three columns of the module docstring from the per-step sums over the live runs of the
    squared errors ``sq_t`` (K, R) and the live-run counts ``alive_t`` (K,) at the times ``time``
    (K,) of steps 1..K."""
    K = time.size
    transient = slice(0, max(1, round(settings.transient * K)))
    steady = slice(K - max(1, round(settings.steady * K)), K)
    steady_rmse = window_rmse(sq_t, alive_t, steady)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms_t = np.sqrt(sq_t / alive_t[:, None])
    settle = [
        convergence_time(time, rms_t[:, j], settings.settle_factor * steady_rmse[j]) for j in range(sq_t.shape[1])
    ]
    return {
        "transient_rmse": window_rmse(sq_t, alive_t, transient),
        "steady_rmse": steady_rmse,
        "time_to_converge_s": np.array(settle, dtype=float),
    }


class _Streams:
    def __init__(self, batch: BatchStart) -> None:
        K, R = batch.time.size - 1, len(state_rows(batch.model))
        self.time = batch.time[1:] - batch.time[0]
        self.sq_t, self.alive_t = np.zeros((K, R)), np.zeros(K)

    def step(self, view: StepView) -> None:
        self.sq_t[view.k - 1] = np.sum(view.rows[view.alive] ** 2, axis=0)
        self.alive_t[view.k - 1] = view.alive.sum()

    def finish(self) -> dict[str, np.ndarray]:
        return {"rows_time": self.time, "rows_sq_t": self.sq_t, "rows_alive_t": self.alive_t}


class Windows(Metric):
    """Streams the per-step sums; the windows are applied when the tables are made, so changing
    them needs no new run."""

    name = "windows"

    def start(self, batch: BatchStart) -> _Streams:
        return _Streams(batch)

    def summary(self, result: EstimatorResult, model: FilterModel, settings: MetricsConf) -> dict[str, np.ndarray]:
        v = result.metric_values
        if "rows_sq_t" not in v:
            R = len(state_rows(model))
            return {name: np.full(R, np.nan) for name in SUMMARY}
        return windowed(v["rows_time"], v["rows_sq_t"], v["rows_alive_t"], settings)

    def summary_columns(self, model: FilterModel) -> tuple[str, ...]:
        return SUMMARY
