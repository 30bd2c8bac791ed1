"""Run estimators over Monte Carlo data and accumulate their metrics step by step.

For every estimator the runner keeps the companion values (thesis: integrated angles and
positions), calls ``predict`` with the previous input and ``update`` with the current
measurement, and accumulates per run: squared errors per state and of the model's derived errors
(:meth:`~quadest.models.base.FilterModel.derived_errors`), NEES, NIS and the wall time of the
filter calls.

Order within a step: ``predict(u_{k−1})``, then ``update`` with the model's primary measurement
(every step), then once per further sensor whose sample is available at step ``k``, in the order
of ``data.sensors`` (``update(z, u, sensor=name)``). NIS is accumulated per sensor.

Errors are ``boxminus(estimate, truth)`` (the model's error state, ``n_err`` components), and the
NEES has ``n_err`` degrees of freedom. An estimator with the ``"random"`` capability receives one
generator per run from ``data.estimator_seeds`` before ``initialize``: fresh generators from the
same seeds for every estimator (common random numbers).

Full covariance histories are never stored; estimates and standard deviations are kept only for
the first ``saved_runs`` runs (for figures and time series).

With a smoother (``estimator.<label>.smoother``, :mod:`quadest.estimators.smoother_settings`)
the filter also keeps its smoother steps (Gaussian) or weighted clouds (particle filters); after
the last step the backward pass runs (:mod:`quadest.estimators.smoothing`,
:mod:`quadest.estimators.particle_smoothing`) and its estimates are scored by a second tracker,
exactly as a filter's are (errors, NEES with the smoothed covariance, saved series), as the
result ``<label>+smoothed`` (fixed interval) or ``<label>+lag<L>`` (fixed lag) in
:attr:`EstimatorResult.smoothed`. A run the filter lost is left out of the smoothed result
entirely. Memory: the K transitions' gains and residuals, ``2 K B n² `` floats (the particle
smoother: the K clouds).

A run is flagged as diverged when the estimator flags it (failed factorisation, non-finite
numbers, an exception in a single-run plugin), when any state error exceeds
``divergence_bound``, or when its covariance is not positive definite. For an estimator whose
covariance only summarises a sample (capability ``"cloud"``: particle filters) a singular
covariance makes that step's NEES unavailable instead (left out of the NEES averages, counted in
``nees_steps``). A diverged run stops contributing from that step on.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from tqdm.auto import tqdm

from quadest.estimators.base import Estimator
from quadest.estimators.particle_smoothing import ffbsi
from quadest.estimators.smoother_settings import SmootherSettings
from quadest.estimators.smoothing import fixed_lag, rts_backward
from quadest.metrics.base import BatchStart, StepView
from quadest.metrics.registry import all_metrics
from quadest.models.base import FilterModel
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult
from quadest.numerics import batched_cholesky, whiten


def _mahalanobis_sq(r: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """``|S⁻¹ r|²`` per run; NaN where the factor is not usable."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return np.sum(whiten(factor, r) ** 2, axis=-1)


def _covariance_factor(est: Estimator) -> np.ndarray:
    """Lower factor of each run's covariance; NaN for runs whose covariance is not PD."""
    if "sqrt_covariance" in est.capabilities:
        return est.sqrt_covariance
    return batched_cholesky(est.covariance)[0]


@dataclass(frozen=True)
class FilterStart:
    """Where every run of an estimator starts: ``x0`` (B, n), ``P0`` (n, n), the companion values
    ``companion0`` (B, nc) and the runs' ``"estimator"`` seeds (see :class:`MonteCarloData`)."""

    x0: np.ndarray
    P0: np.ndarray
    companion0: np.ndarray
    estimator_seeds: list[np.random.SeedSequence]

    @classmethod
    def of(cls, data: MonteCarloData) -> FilterStart:
        return cls(data.x0, data.P0, data.companion0, data.estimator_seeds)


class EstimatorTracker:
    """Steps one estimator through a batch and accumulates its metrics, one sample at a time.

    :func:`run_estimator` drives it over recorded data; the closed loop
    (:mod:`quadest.closed_loop.feedback`) drives it with each sample as its plant produces it.
    ``truth`` and ``companion_truth`` passed to :meth:`step` are this estimator's own.
    """

    def __init__(
        self,
        name: str,
        est: Estimator,
        model: FilterModel,
        start: FilterStart,
        steps: int,
        divergence_bound: float,
        saved_runs: int = 0,
        sensor_names: tuple[str, ...] = (),
        sample_times: np.ndarray | None = None,
    ) -> None:
        B, K1 = start.x0.shape[0], steps + 1
        n, nc = model.n_err, start.companion0.shape[-1]
        self.name, self.est, self.model, self.bound = name, est, model, divergence_bound
        self.K = steps
        self.saved_runs = saved_runs = min(saved_runs, B)
        self.sq, self.csq, self.steps = np.zeros((B, n)), np.zeros((B, nc)), np.zeros(B)
        self.dsq = np.zeros((B, len(model.derived_error_names)))
        self.nees_sum, self.nis_sum, self.nees_steps = np.zeros(B), np.zeros(B), np.zeros(B)
        self.nees_t, self.nis_t, self.alive_t = np.full(K1, np.nan), np.full(K1, np.nan), np.zeros(K1)
        self.sq_t = np.zeros((K1, n))
        self.diverged = np.zeros(B, dtype=bool)
        self.diverged_step = np.full(B, -1)
        self.reasons: dict[int, str] = {}
        self.est_hist = np.full((saved_runs, K1, start.x0.shape[-1]), np.nan)
        self.std_hist = np.full((saved_runs, K1, n), np.nan)
        self.comp_hist = np.full((saved_runs, K1, nc), np.nan)
        self.has_innovation = "innovation" in est.capabilities
        self.is_cloud = not {"cloud", "no_covariance"}.isdisjoint(est.capabilities)  # NEES may be unavailable
        self.sensor_nis = {s: (np.zeros(B), np.zeros(B)) for s in sensor_names}
        self.elapsed = 0.0
        batch = BatchStart(model, np.arange(K1) * model.dt if sample_times is None else sample_times, B)
        self.accumulators = [acc for metric in all_metrics() if (acc := metric.start(batch)) is not None]
        if "random" in est.capabilities:
            est.set_generators([np.random.default_rng(seed) for seed in start.estimator_seeds])
        t0 = time.perf_counter()
        est.initialize(start.x0.copy(), np.broadcast_to(start.P0, (B, n, n)).copy())
        self.elapsed += time.perf_counter() - t0
        self.companion = start.companion0.copy()
        self._record(0)

    def flag(self, mask: np.ndarray, k: int, why) -> None:
        """Mark the runs of ``mask`` diverged at step ``k`` (a reason text, or run → text)."""
        for i in np.flatnonzero(mask & ~self.diverged):
            self.diverged[i], self.diverged_step[i] = True, k
            self.reasons[int(i)] = why(int(i)) if callable(why) else why

    def _record(self, k: int) -> None:
        """Keep the first ``saved_runs`` series; a diverged run shows NaN, not its placeholder."""
        s = self.saved_runs
        if not s:
            return
        keep = ~self.diverged[:s, None]
        self.est_hist[:, k] = np.where(keep, self.est.mean[:s], np.nan)
        var = np.diagonal(self.est.covariance[:s], axis1=-2, axis2=-1)
        self.std_hist[:, k] = np.where(keep, np.sqrt(np.clip(var, 0, None)), np.nan)
        self.comp_hist[:, k] = np.where(keep, self.companion[:s], np.nan)

    def _innovation(self) -> tuple[np.ndarray, np.ndarray]:
        """The last update's innovation and its covariance factor, copied (the next update may
        overwrite the estimator's own arrays)."""
        nu, factor = self.est.innovation()
        return np.array(nu, copy=True), np.array(factor, copy=True)

    def _update_sensors(self, further: list[tuple[str, np.ndarray]], u_now: np.ndarray, innovations: dict) -> float:
        """Further sensors available at this step, in order, with their NIS; their innovations go
        into ``innovations``; returns the filter time."""
        spent = 0.0
        for sensor_name, z in further:
            t0 = time.perf_counter()
            self.est.update(z, u_now, sensor=sensor_name)
            spent += time.perf_counter() - t0
            if self.has_innovation:
                innovations[sensor_name] = self._innovation()
                total, count = self.sensor_nis[sensor_name]
                nis_s = _mahalanobis_sq(*innovations[sensor_name])
                live = ~self.diverged & np.isfinite(nis_s)
                total[live] += nis_s[live]
                count[live] += 1
        return spent

    def step(
        self,
        k: int,
        u_prev: np.ndarray,
        u_now: np.ndarray,
        z: np.ndarray,
        truth: np.ndarray,
        companion_truth: np.ndarray,
        further: list[tuple[str, np.ndarray]] = (),
    ) -> None:
        """Step ``k``: ``predict`` with the measured input of sample k−1, ``update`` with sample k's
        primary measurement ``z`` and then the ``further`` (name, values) samples; score against
        ``truth`` (B, n) and ``companion_truth`` (B, nc) of sample k."""
        est, model, B = self.est, self.model, self.diverged.shape[0]
        next_companion = model.companion_step(self.companion, est.mean)
        u_prev = model.filter_input(u_prev, self.companion)
        self.companion = next_companion
        u_now = model.filter_input(u_now, self.companion)
        t0 = time.perf_counter()
        est.predict(u_prev)
        est.update(z, u_now)
        self.elapsed += time.perf_counter() - t0
        innovations = {None: self._innovation()} if self.has_innovation else {}
        nis = _mahalanobis_sq(*innovations[None]) if self.has_innovation else np.full(B, np.nan)
        self.elapsed += self._update_sensors(list(further), u_now, innovations)
        self.flag(est.failed, k, lambda i: est.failure_reasons.get(i, "flagged by the estimator"))

        err = model.boxminus(est.mean, truth)
        with np.errstate(invalid="ignore"):
            too_big = ~(np.abs(err) <= self.bound).all(-1)
        self.flag(too_big, k, f"state error beyond divergence_bound={self.bound}")
        factor = _covariance_factor(est)
        nees = _mahalanobis_sq(err, factor)
        if not self.is_cloud:
            self.flag(~np.isfinite(nees), k, "covariance not positive definite")
        nees_ok = np.isfinite(nees)

        alive = ~self.diverged
        self.sq[alive] += err[alive] ** 2
        self.csq[alive] += (self.companion[alive] - companion_truth[alive]) ** 2
        derived = np.full((B, self.dsq.shape[1]), np.nan)
        derived[alive] = model.derived_errors(est.mean[alive], truth[alive])
        self.dsq[alive] += derived[alive] ** 2
        self.steps[alive] += 1
        counted = alive & nees_ok
        self.nees_sum[counted] += nees[counted]
        self.nees_steps[counted] += 1
        self.nis_sum[alive] += nis[alive]
        self.alive_t[k] = alive.sum()
        self.sq_t[k] = (err[alive] ** 2).sum(axis=0)
        if counted.any():
            self.nees_t[k] = nees[counted].mean()
        if alive.any():
            self.nis_t[k] = nis[alive].mean()
        view = StepView(k, err, derived, self.companion - companion_truth, factor, nees, nis, alive, innovations)
        for accumulator in self.accumulators:
            accumulator.step(view)
        self._record(k)

    def result(self) -> EstimatorResult:
        """The accumulated metrics (call once, after the last step)."""
        est, B = self.est, self.diverged.shape[0]
        saved = {"estimate": self.est_hist, "std": self.std_hist, "companion": self.comp_hist}
        diagnostics = {
            key: np.where(self.diverged, np.nan, np.asarray(v, dtype=float)) for key, v in est.diagnostics().items()
        }
        return EstimatorResult(
            name=self.name, sq_error_sum=self.sq, companion_sq_error_sum=self.csq, steps=self.steps,
            nees_sum=self.nees_sum, nis_sum=self.nis_sum, nees_mean_t=self.nees_t, nis_mean_t=self.nis_t,
            sq_error_t=self.sq_t, alive_t=self.alive_t, diverged=self.diverged, diverged_step=self.diverged_step,
            reasons=self.reasons, step_time_us=self.elapsed / self.K / B * 1e6, saved=saved,
            sensor_nis=self.sensor_nis, nees_steps=self.nees_steps, diagnostics=diagnostics,
            derived_sq_error_sum=self.dsq,
            metric_values={k: v for acc in self.accumulators for k, v in acc.finish().items()},
        )  # fmt: skip


class _Replay(Estimator):
    """Plays stored estimates back through an :class:`EstimatorTracker`: ``initialize`` shows step 0,
    each primary ``update`` the next step (a smoother's estimates, scored like a filter's)."""

    def __init__(self, model: FilterModel, means: np.ndarray, spreads: np.ndarray, capabilities: frozenset[str]):
        super().__init__(model)
        self.means, self.spreads, self.k = means, spreads, 0
        self.capabilities = capabilities  # type: ignore[misc]

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self.k = 0
        self._reset_failures(x0.shape[0])

    def predict(self, u: np.ndarray) -> None:
        return None

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        if sensor is None:
            self.k += 1

    @property
    def mean(self) -> np.ndarray:
        return self.means[self.k]

    @property
    def covariance(self) -> np.ndarray:
        S = self.spreads[self.k]
        return S @ np.swapaxes(S, -1, -2) if "sqrt_covariance" in self.capabilities else S

    @property
    def sqrt_covariance(self) -> np.ndarray:
        return self.spreads[self.k]


class SmoothingRecorder:
    """Keeps what the backward pass needs while a filter runs forward: for a Gaussian filter the
    filtered means (and spreads, for a fixed lag) of steps 0..K and the K smoother steps; for a
    particle filter the K weighted clouds and the initial moments."""

    def __init__(self, est: Estimator, settings: SmootherSettings) -> None:
        self.est, self.settings = est, settings
        self.particles = "particle_smoothing" in est.capabilities
        self.square_root = "sqrt_covariance" in est.capabilities
        est.smoothing = True
        self.means: list[np.ndarray] = []
        self.spreads: list[np.ndarray] = []
        self.steps: list = []
        self.clouds: list = []

    def _spread(self) -> np.ndarray:
        return (self.est.sqrt_covariance if self.square_root else self.est.covariance).copy()

    def start(self) -> None:
        """After ``initialize``: step 0."""
        self.means.append(self.est.mean.copy())
        self.spreads.append(self._spread())

    def record(self) -> None:
        """After the updates of step k ≥ 1."""
        if self.particles:
            self.clouds.append(self.est.smoother_cloud)
            return
        self.steps.append(self.est.smoother_step)
        self.means.append(self.est.mean.copy())
        if self.settings.kind in ("fixed_lag", "iterated"):
            self.spreads.append(self._spread())
        else:
            self.spreads[-1:] = [self._spread()]  # only the last is needed

    def smooth(self, model: FilterModel, start: FilterStart) -> tuple[np.ndarray, np.ndarray, frozenset[str]]:
        """Smoothed means (K+1, B, n), spreads (K+1, B, n, n) and the capabilities of their replay."""
        if self.particles:
            rngs = [np.random.default_rng(smoother_seed(seed)) for seed in start.estimator_seeds]
            means, covs = ffbsi(self.clouds, model, rngs, self.settings.trajectories)
            return (
                np.concatenate([self.means[0][None], means]),
                np.concatenate([self.spreads[0][None], covs]),
                frozenset({"cloud"}),
            )
        if self.settings.kind == "iterated":
            means, covs = self.est.iterated_smoothing(
                self.settings.iterations, np.array(self.means), np.array(self.spreads)
            )
            return means, covs, frozenset()
        form = self.est.smoothing_form()
        if self.settings.kind == "fixed_lag":
            means, spreads = fixed_lag(self.means, self.spreads, self.steps, form, self.settings.lag)
        else:
            means, spreads = rts_backward(self.means, self.spreads[-1], self.steps, form)
        return means, spreads, frozenset({"sqrt_covariance"} if form.square_root else ())


SMOOTHER_STREAM = 7  # the particle smoother's draws: a child of each run's estimator stream


def smoother_seed(seed: np.random.SeedSequence) -> np.random.SeedSequence:
    """The seed of a run's particle-smoother draws: a fixed child of the run's estimator seed, the
    same for every estimator (common random numbers) and whatever else has been spawned."""
    return np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, SMOOTHER_STREAM))


def run_estimator(
    name: str,
    est: Estimator,
    data: MonteCarloData,
    divergence_bound: float,
    saved_runs: int = 0,
    progress: bool = False,
    crashes: tuple[np.ndarray, dict[int, str]] | None = None,
    smoother: SmootherSettings | None = None,
) -> EstimatorResult:
    """Filter every run of ``data`` with ``est`` and accumulate the metrics; with ``smoother``, also
    smooth and score the smoothed estimates (:attr:`EstimatorResult.smoothed`).

    ``crashes`` = (crash step (B,), −1 for none; run → reason) ends the runs of a closed-loop
    flight that crashed: each is flagged at the sample after its crash and stops counting."""
    recorder = SmoothingRecorder(est, smoother) if smoother is not None else None
    tracker = EstimatorTracker(
        name, est, data.model, FilterStart.of(data), data.time.size - 1, divergence_bound, saved_runs,
        tuple(data.sensors), data.time,
    )  # fmt: skip
    if recorder is not None:
        recorder.start()
    bar = tqdm(
        total=tracker.K, desc=f"{name:>8s}", unit="step", disable=None if progress else True, leave=False,
        mininterval=0.5,
    )  # fmt: skip
    crash_step, crash_reasons = crashes if crashes is not None else (np.full(data.x0.shape[0], -1), {})
    for k in range(1, tracker.K + 1):
        tracker.flag((crash_step >= 0) & (crash_step < k), k, lambda i: f"vehicle crashed: {crash_reasons[i]}")
        further = [(s, rec.values[:, k]) for s, rec in data.sensors.items() if rec.available[k]]
        tracker.step(
            k, data.inputs[:, k - 1], data.inputs[:, k], data.measurements[:, k], data.truth[:, k],
            data.companion_truth[:, k], further,
        )  # fmt: skip
        if recorder is not None:
            recorder.record()
        bar.update()
    bar.close()
    result = tracker.result()
    if recorder is None:
        return result
    return replace(result, smoothed=_smoothed_result(result, recorder, data, divergence_bound, saved_runs))


def _smoothed_result(
    filtered: EstimatorResult, recorder: SmoothingRecorder, data: MonteCarloData, bound: float, saved_runs: int
) -> EstimatorResult:
    """The smoothed estimates of ``recorder`` scored against the data's truth, as a result named
    ``<label>+smoothed`` / ``<label>+lag<L>``; its step time is the backward pass's."""
    start = FilterStart.of(data)
    t0 = time.perf_counter()
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        means, spreads, capabilities = recorder.smooth(data.model, start)
    elapsed = time.perf_counter() - t0
    replay = _Replay(data.model, means, spreads, capabilities)
    tracker = EstimatorTracker(
        filtered.name + recorder.settings.label_suffix, replay, data.model, start, data.time.size - 1, bound,
        saved_runs, tuple(data.sensors), data.time,
    )  # fmt: skip
    tracker.flag(filtered.diverged, 1, lambda i: f"left out: the filter lost this run ({filtered.reasons.get(i, '')})")
    for k in range(1, tracker.K + 1):
        tracker.step(k, data.inputs[:, k - 1], data.inputs[:, k], data.measurements[:, k], data.truth[:, k],
                     data.companion_truth[:, k])  # fmt: skip
    tracker.elapsed = elapsed
    return tracker.result()
