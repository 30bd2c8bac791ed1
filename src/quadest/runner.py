"""Run estimators over Monte Carlo data and accumulate their metrics step by step.

For every estimator the runner keeps the companion values (thesis: integrated angles and
positions), calls ``predict`` with the previous input and ``update`` with the current
measurement, and accumulates per run: squared errors per state, NEES, NIS and the wall time of
the filter calls.

Order within a step: ``predict(u_{k−1})``, then ``update`` with the model's primary measurement
(every step), then once per further sensor whose sample is available at step ``k``, in the order
of ``data.sensors`` (``update(z, u, sensor=name)``). NIS is accumulated per sensor.

Errors are ``boxminus(estimate, truth)`` (the model's error state, ``n_err`` components), and the
NEES has ``n_err`` degrees of freedom. An estimator with the ``"random"`` capability receives one
generator per run from ``data.estimator_seeds`` before ``initialize``: fresh generators from the
same seeds for every estimator (common random numbers).

Full covariance histories are never stored; estimates and standard deviations are kept only for
the first ``saved_runs`` runs (for figures and time series).

A run is flagged as diverged when the estimator flags it (failed factorisation, non-finite
numbers, an exception in a single-run plugin), when any state error exceeds
``divergence_bound``, or when its covariance is not positive definite. For an estimator whose
covariance only summarises a sample (capability ``"cloud"``: particle filters) a singular
covariance makes that step's NEES unavailable instead (left out of the NEES averages, counted in
``nees_steps``). A diverged run stops contributing from that step on.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from tqdm.auto import tqdm

from quadest.estimators.base import Estimator
from quadest.montecarlo import MonteCarloData
from quadest.numerics import batched_cholesky, whiten


@dataclass
class EstimatorResult:
    """What one estimator achieved on one batch.

    Attributes:
        name: the estimator's label (its key under ``estimator.``).
        sq_error_sum: (B, n) sum over steps 1..K of squared state errors.
        companion_sq_error_sum: (B, nc) the same for the companion values.
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


def _mahalanobis_sq(r: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """``|S⁻¹ r|²`` per run; NaN where the factor is not usable."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return np.sum(whiten(factor, r) ** 2, axis=-1)


def _covariance_factor(est: Estimator) -> np.ndarray:
    """Lower factor of each run's covariance; NaN for runs whose covariance is not PD."""
    if "sqrt_covariance" in est.capabilities:
        return est.sqrt_covariance
    return batched_cholesky(est.covariance)[0]


def run_estimator(
    name: str,
    est: Estimator,
    data: MonteCarloData,
    divergence_bound: float,
    saved_runs: int = 0,
    progress: bool = False,
) -> EstimatorResult:
    """Filter every run of ``data`` with ``est`` and accumulate the metrics."""
    model = data.model
    B, K1 = data.truth.shape[:2]
    n = model.n_err
    K = K1 - 1
    nc = data.companion_truth.shape[-1]
    saved_runs = min(saved_runs, B)
    sq = np.zeros((B, n))
    csq = np.zeros((B, nc))
    steps = np.zeros(B)
    nees_sum, nis_sum, nees_steps = np.zeros(B), np.zeros(B), np.zeros(B)
    nees_t, nis_t, alive_t = np.full(K1, np.nan), np.full(K1, np.nan), np.zeros(K1)
    sq_t = np.zeros((K1, n))
    diverged = np.zeros(B, dtype=bool)
    diverged_step = np.full(B, -1)
    reasons: dict[int, str] = {}
    est_hist = np.full((saved_runs, K1, data.truth.shape[-1]), np.nan)
    std_hist = np.full((saved_runs, K1, n), np.nan)
    comp_hist = np.full((saved_runs, K1, nc), np.nan)

    def flag(mask: np.ndarray, k: int, why) -> None:
        for i in np.flatnonzero(mask & ~diverged):
            diverged[i], diverged_step[i] = True, k
            reasons[int(i)] = why(int(i)) if callable(why) else why

    def record(k: int) -> None:
        """Keep the first ``saved_runs`` series; a diverged run shows NaN, not its placeholder."""
        if not saved_runs:
            return
        keep = ~diverged[:saved_runs, None]
        est_hist[:, k] = np.where(keep, est.mean[:saved_runs], np.nan)
        var = np.diagonal(est.covariance[:saved_runs], axis1=-2, axis2=-1)
        std_hist[:, k] = np.where(keep, np.sqrt(np.clip(var, 0, None)), np.nan)
        comp_hist[:, k] = np.where(keep, companion[:saved_runs], np.nan)

    elapsed = 0.0
    if "random" in est.capabilities:
        est.set_generators([np.random.default_rng(seed) for seed in data.estimator_seeds])
    t0 = time.perf_counter()
    P0 = np.broadcast_to(data.P0, (B, n, n)).copy()
    est.initialize(data.x0.copy(), P0)
    elapsed += time.perf_counter() - t0
    companion = data.companion0.copy()
    record(0)
    has_innovation = "innovation" in est.capabilities
    is_cloud = "cloud" in est.capabilities
    sensor_nis = {name: (np.zeros(B), np.zeros(B)) for name in data.sensors}

    def update_sensors(k: int, u_now: np.ndarray) -> float:
        """Further sensors available at step k, in order, with their NIS; returns the filter time."""
        spent = 0.0
        for sensor_name, sensor in data.sensors.items():
            if not sensor.available[k]:
                continue
            t0 = time.perf_counter()
            est.update(sensor.values[:, k], u_now, sensor=sensor_name)
            spent += time.perf_counter() - t0
            if has_innovation:
                total, count = sensor_nis[sensor_name]
                nis_s = _mahalanobis_sq(*est.innovation())
                live = ~diverged & np.isfinite(nis_s)
                total[live] += nis_s[live]
                count[live] += 1
        return spent

    bar = tqdm(
        total=K, desc=f"{name:>8s}", unit="step", disable=None if progress else True, leave=False, mininterval=0.5
    )
    for k in range(1, K1):
        next_companion = model.companion_step(companion, est.mean)
        u_prev = model.filter_input(data.inputs[:, k - 1], companion)
        companion = next_companion
        u_now = model.filter_input(data.inputs[:, k], companion)
        t0 = time.perf_counter()
        est.predict(u_prev)
        est.update(data.measurements[:, k], u_now)
        elapsed += time.perf_counter() - t0
        nis = _mahalanobis_sq(*est.innovation()) if has_innovation else np.full(B, np.nan)
        elapsed += update_sensors(k, u_now)
        flag(est.failed, k, lambda i: est.failure_reasons.get(i, "flagged by the estimator"))

        err = model.boxminus(est.mean, data.truth[:, k])
        with np.errstate(invalid="ignore"):
            too_big = ~(np.abs(err) <= divergence_bound).all(-1)
        flag(too_big, k, f"state error beyond divergence_bound={divergence_bound}")
        nees = _mahalanobis_sq(err, _covariance_factor(est))
        if not is_cloud:
            flag(~np.isfinite(nees), k, "covariance not positive definite")
        nees_ok = np.isfinite(nees)

        alive = ~diverged
        sq[alive] += err[alive] ** 2
        csq[alive] += (companion[alive] - data.companion_truth[alive, k]) ** 2
        steps[alive] += 1
        counted = alive & nees_ok
        nees_sum[counted] += nees[counted]
        nees_steps[counted] += 1
        nis_sum[alive] += nis[alive]
        alive_t[k] = alive.sum()
        sq_t[k] = (err[alive] ** 2).sum(axis=0)
        if counted.any():
            nees_t[k] = nees[counted].mean()
        if alive.any():
            nis_t[k] = nis[alive].mean()
        record(k)
        bar.update()
    bar.close()
    saved = {"estimate": est_hist, "std": std_hist, "companion": comp_hist}
    diagnostics = {key: np.where(diverged, np.nan, np.asarray(v, dtype=float)) for key, v in est.diagnostics().items()}
    return EstimatorResult(
        name=name, sq_error_sum=sq, companion_sq_error_sum=csq, steps=steps, nees_sum=nees_sum, nis_sum=nis_sum,
        nees_mean_t=nees_t, nis_mean_t=nis_t, sq_error_t=sq_t, alive_t=alive_t, diverged=diverged,
        diverged_step=diverged_step, reasons=reasons, step_time_us=elapsed / K / B * 1e6, saved=saved,
        sensor_nis=sensor_nis, nees_steps=nees_steps, diagnostics=diagnostics,
    )  # fmt: skip
