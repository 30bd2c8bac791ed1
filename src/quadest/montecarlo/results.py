"""What an estimator achieved on a batch of Monte Carlo runs: :class:`EstimatorResult`.

The runner (:mod:`quadest.runner`) and the closed loop fill it; the cache, the metrics, the tables
and the figures read it without depending on the runner.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.montecarlo.data import MonteCarloData


@dataclass
class EstimatorResult:
    """What one estimator achieved on one batch.

    Attributes:
        name: the estimator's label (its key under ``estimator.``).
        sq_error_sum: (B, n) sum over steps 1..K of squared state errors.
        companion_sq_error_sum: (B, nc) the same for the companion values.
        derived_sq_error_sum: (B, d) the same for the model's derived errors
            (:meth:`~quadest.models.base.FilterModel.derived_errors`, e.g. roll, pitch, yaw).
        steps: (B,) number of steps that counted (K unless the run diverged).
        nees_sum, nis_sum: (B,) sums over counted steps (NIS: the primary measurement).
        nees_steps: (B,) steps whose NEES was available (fewer than ``steps`` only for "cloud"
            estimators whose covariance was singular at some steps).
        diagnostics: the estimator's per-run diagnostics (name → (B,)), NaN for diverged runs.
        sensor_nis: sensor name → (NIS sum (B,), number of updates (B,)) for further sensors.
        nees_mean_t, nis_mean_t: (K+1,) averages over the runs alive at each step.
        sq_error_t: (K+1, n) squared state errors summed over the runs alive at each step.
        alive_t: (K+1,) number of runs alive at each step.
        diverged: (B,) bool; diverged_step: (B,) first step flagged (-1 if none).
        reasons: run → reason text.
        step_time_us: wall time of predict + update per step per run (batch time / B).
        saved: time series of the first runs: ``estimate``, ``std``, ``companion``.
        smoothed: with a smoother, the smoothed estimates' result (another row of the tables,
            named ``<label>+smoothed`` or ``<label>+lag<L>``); ``None`` otherwise.
        truth, companion_truth: the truth this estimator was scored against, first runs only
            (closed loop with the estimate fed back: each estimator flies its own truth; ``None``
            when the truth is the data's, shared by every estimator).
        flight: closed loop with the estimate fed back: what the job keeps of the flight this
            estimator flew (:class:`quadest.closed_loop.loop.FlightRecord`), cached with the
            result; ``None`` otherwise.
        metric_values: what the streaming metrics (:mod:`quadest.metrics`) kept of the batch, by
            name (their columns, or the per-step sums their tables are made from).
    """

    name: str
    sq_error_sum: np.ndarray
    companion_sq_error_sum: np.ndarray
    steps: np.ndarray
    nees_sum: np.ndarray
    nis_sum: np.ndarray
    nees_mean_t: np.ndarray
    nis_mean_t: np.ndarray
    sq_error_t: np.ndarray
    alive_t: np.ndarray
    diverged: np.ndarray
    diverged_step: np.ndarray
    reasons: dict[int, str]
    step_time_us: float
    saved: dict[str, np.ndarray] = field(default_factory=dict)
    sensor_nis: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    nees_steps: np.ndarray | None = None
    diagnostics: dict[str, np.ndarray] = field(default_factory=dict)
    truth: np.ndarray | None = None
    companion_truth: np.ndarray | None = None
    derived_sq_error_sum: np.ndarray | None = None
    smoothed: EstimatorResult | None = None
    flight: object | None = None
    metric_values: dict[str, np.ndarray] = field(default_factory=dict)

    def _per_run(self, totals: np.ndarray, root: bool = False) -> np.ndarray:
        """Time averages of per-run sums (square-rooted for RMSE); NaN for diverged runs."""
        steps = self.steps.reshape(self.steps.shape + (1,) * (totals.ndim - 1))
        with np.errstate(invalid="ignore", divide="ignore"):
            out = totals / steps
        out = np.sqrt(out) if root else out
        out[self.diverged] = np.nan
        return out

    @property
    def rmse(self) -> np.ndarray:
        """(B, n) per-run RMSE over time; NaN for diverged runs."""
        return self._per_run(self.sq_error_sum, root=True)

    @property
    def derived_rmse(self) -> np.ndarray:
        """(B, d) per-run RMSE of the derived errors; NaN for diverged runs."""
        return self._per_run(self.derived_sq_error_sum, root=True)

    @property
    def companion_rmse(self) -> np.ndarray:
        """(B, nc) per-run RMSE of the companion values."""
        return self._per_run(self.companion_sq_error_sum, root=True)

    @property
    def mean_nees(self) -> np.ndarray:
        """(B,) per-run time-average NEES over the steps where it was available."""
        steps = self.steps if self.nees_steps is None else self.nees_steps
        with np.errstate(invalid="ignore", divide="ignore"):
            out = self.nees_sum / steps
        out[self.diverged] = np.nan
        return out

    @property
    def mean_nis(self) -> np.ndarray:
        """(B,) per-run time-average NIS (NaN without the innovation capability)."""
        return self._per_run(self.nis_sum)

    def mean_sensor_nis(self, sensor: str) -> np.ndarray:
        """(B,) per-run average NIS of a further sensor over its updates; NaN for diverged runs."""
        total, count = self.sensor_nis[sensor]
        with np.errstate(invalid="ignore", divide="ignore"):
            out = total / count
        out[self.diverged] = np.nan
        return out


def failed_result(name: str, data: MonteCarloData, reason: str) -> EstimatorResult:
    """The result of an estimator that could not run at all: every run flagged with ``reason``."""
    B, K1, n = data.truth.shape
    n_err, nc = data.model.n_err, data.companion_truth.shape[-1]
    nan = np.full(B, np.nan)
    return EstimatorResult(
        name=name, sq_error_sum=np.full((B, n_err), np.nan), companion_sq_error_sum=np.full((B, nc), np.nan),
        steps=np.zeros(B), nees_sum=nan, nis_sum=nan.copy(), nees_mean_t=np.full(K1, np.nan),
        nis_mean_t=np.full(K1, np.nan), sq_error_t=np.zeros((K1, n_err)), alive_t=np.zeros(K1),
        diverged=np.ones(B, dtype=bool), diverged_step=np.zeros(B, dtype=int), reasons=dict.fromkeys(range(B), reason),
        step_time_us=float("nan"), derived_sq_error_sum=np.full((B, len(data.model.derived_error_names)), np.nan),
        saved={"estimate": np.full((0, K1, n), np.nan), "std": np.full((0, K1, n_err), np.nan),
               "companion": np.full((0, K1, nc), np.nan)},
    )  # fmt: skip
