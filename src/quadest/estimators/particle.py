"""Particle filters batched over Monte Carlo runs, and the bootstrap filter (``estimator=pf``).

Every run of a batch carries its own cloud: particles ``x`` (B, N, n) beside normalised
log-weights (B, N), plus any per-particle arrays a proposal needs (the EKF proposal's P_i,
(B, N, n, n)) in :attr:`ParticleFilter.particle_state`, which resampling carries along. Every
operation works on all particles of all runs at once, and every run draws from its own generator
(capability ``"random"``), so a run in a batch gets exactly the numbers it gets alone. On the
numba backend (``QUADEST_KERNELS``, docs/benchmarks.md) the draws, the Gaussian log-densities, the
normalisation with the ESS, the resampling and the gather of the particles are compiled kernels
(:mod:`quadest.numerics.particle_kernels`) that give their numpy references' numbers bit for bit.
The bootstrap filter's ``kernel: fast`` (:class:`BootstrapPF`) trades that for a fused step whose
numbers agree with the exact mode's within Monte Carlo error (:mod:`quadest.numerics.fast_bootstrap`).

One step (sequential importance sampling with resampling; Gordon, Salmond & Smith 1993; Doucet,
Godsill & Andrieu 2000, "On sequential Monte Carlo sampling methods for Bayesian filtering"):

1. the proposal draws ``x_k^i ~ q(· | x_{k−1}^i, y_k)`` (:meth:`ParticleFilter.propose`);
2. incremental weights ``p(y_k | x_k^i) p(x_k^i | x_{k−1}^i) / q(x_k^i | x_{k−1}^i, y_k)``, with
   the model's own noise densities: ``measurement_noise_logpdf(y − h(x))`` and
   ``process_noise_logpdf(x − f(x_prev))`` (additive noise). For the transition prior as the
   proposal (bootstrap) the last two cancel and only the likelihood is computed;
3. the estimate, before (``estimate: weighted``) or after (``estimate: resampled``) resampling:
   the weighted mean and covariance of the cloud;
4. resampling (:mod:`quadest.numerics.resampling`), every step or when ESS < ``ess_threshold``·N;
   optional roughening (Gordon et al. 1993, §4: Gaussian jitter with standard deviation
   ``K E_j N^(−1/n)``, ``E_j`` the spread of coordinate j in the cloud, ``K = roughening``).

``predict`` only records the input: the guided proposals need ``y_k``, so the whole step happens in
``update``. A run whose weights all vanish (every likelihood underflows, or every proposed
particle lies outside the transition's support) is flagged with that reason and parked on its
initial cloud, never a crash (``vanished_weights: flag``, the default); with
``vanished_weights: uniform`` it carries on with equal weights on the proposed cloud instead.

Weights (``weights``): ``log``, the default, is the exact computation, normalised in the log
domain (:func:`~quadest.numerics.resampling.normalise_log_weights`). ``linear_floor`` is the
numerics of the public demo code of van der Merwe, Doucet, de Freitas & Wan (2000)
(``demo_MC.m``): the likelihood gets an additive floor in the linear domain,
``(p(y_k | x_k^i) + weight_floor) · p(x_k^i | x_{k−1}^i) / q(x_k^i)`` ("deal with
ill-conditioning", floor 1e-99). When no particle explains ``y_k`` (every likelihood below the
floor) the floor decides: the bootstrap filter's weights become equal and that step does not
correct the cloud. We add the floor to the normalised density ``(2π)^(−m/2)|R|^(−1/2) exp(·)``;
the demo's lacks the ``(2π)^(−1/2)``, which moves the threshold by that factor only. The sum is
formed as ``logaddexp`` (the same number to rounding, without the demo's underflow of a product).

Outputs besides the moments: :attr:`ess` (B,) of the last step before resampling,
:attr:`ess_sum`, :attr:`resample_count` and :attr:`outside_support` (B,) over the run: the
number of proposed particles whose transition density was zero; :meth:`ParticleFilter.diagnostics`
hands them to the runner, so they are columns of ``metrics.csv``. The covariance only summarises
the cloud (capability ``"cloud"``): a collapsed cloud makes that step's NEES unavailable, it does
not count as divergence.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from quadest.errors import ConfigError
from quadest.estimators.base import Estimator
from quadest.estimators.params import ranged
from quadest.estimators.particle_smoothing import ParticleCloud
from quadest.models.base import FilterModel
from quadest.numerics import psd_sqrt
from quadest.numerics.draws import particle_kernels, standard_normals, warm_up_particle_kernels
from quadest.numerics.fast_bootstrap import (
    FAST_SCHEMES,
    draw_step_uniforms,
    fast_bootstrap_step,
    measurement_whitening,
    warm_up_fast_step,
)
from quadest.numerics.resampling import (
    RESAMPLING_SCHEMES,
    check_scheme,
    normalised_weights,
    resample,
)

SCHEDULES = ("every_step", "ess")
ESTIMATES = ("weighted", "resampled")
INITIAL_CLOUDS = ("sample", "point", "uniform")
WEIGHTS = ("log", "linear_floor")
VANISHED_POLICIES = ("flag", "uniform")
CHOICES = {
    "resampling": RESAMPLING_SCHEMES,
    "schedule": SCHEDULES,
    "estimate": ESTIMATES,
    "initial_cloud": INITIAL_CLOUDS,
    "weights": WEIGHTS,
    "vanished_weights": VANISHED_POLICIES,
}


@dataclass
class ParticleParams:
    """Options every particle filter shares (``conf/estimator/pf.yaml`` explains each)."""

    kind: str = "pf"
    particles: int = ranged(500, "particles per run", ge=2, integer=True)
    resampling: str = "systematic"
    schedule: str = "every_step"
    ess_threshold: float = ranged(0.5, "resample when ESS < ess_threshold * N (schedule: ess)", gt=0.0, le=1.0)
    estimate: str = "weighted"
    roughening: float = ranged(0.0, "roughening constant K (0: none)", ge=0.0)
    initial_cloud: str = "sample"
    initial_range: list[float] = field(default_factory=lambda: [0.0, 1.0])
    weights: str = "log"
    weight_floor: float = ranged(1e-99, "additive floor of the likelihood (weights: linear_floor)", gt=0.0)
    vanished_weights: str = "flag"

    @staticmethod
    def constraints(values: Mapping[str, Any], n: int) -> list[tuple[str, Any, str]]:
        """The choice options and ``initial_range``, checked before any work."""
        return particle_constraints(values)


def range_problem(value: Any) -> str | None:
    """Why ``value`` is not a valid ``initial_range`` ``[low, high]``, or ``None``."""
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        return "a list [low, high] of two finite numbers with low < high"
    if not (np.isfinite(low) and np.isfinite(high) and low < high):
        return "a list [low, high] of two finite numbers with low < high"
    return None


def particle_constraints(values: Mapping[str, Any]) -> list[tuple[str, Any, str]]:
    """``(key, value, allowed)`` for every choice option of :data:`CHOICES` outside its values
    and a malformed ``initial_range``."""
    problems = [
        (key, values[key], f"one of {list(allowed)}")
        for key, allowed in CHOICES.items()
        if key in values and values[key] not in allowed
    ]
    if "initial_range" in values and (why := range_problem(values["initial_range"])) is not None:
        problems.append(("initial_range", values["initial_range"], why))
    return problems


def one_of(key: str, value: str, allowed: tuple[str, ...]) -> None:
    """Raise :class:`ConfigError` unless ``value`` is in ``allowed``."""
    if value not in allowed:
        raise ConfigError(key, value, f"one of {list(allowed)}")


def gather_particles(arrays: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """``arrays`` (B, N, ...) picked along the particle axis by ``indices`` (B, N')."""
    B, N = arrays.shape[:2]
    flat = (indices + N * np.arange(B)[:, None]).ravel()
    return arrays.reshape(B * N, *arrays.shape[2:])[flat].reshape(*indices.shape, *arrays.shape[2:])


def weighted_moments(x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (B, n) and covariance (B, n, n) of clouds ``x`` (B, N, n) with weights ``w`` (B, N)
    (particles of zero weight, possibly non-finite, are left out)."""
    if not np.all(w > 0):  # 0 · NaN would be NaN; a zeroed particle adds exactly 0 to both sums
        x = np.where(w[..., None] > 0, x, 0.0)
    mean = np.einsum("bk,bki->bi", w, x)
    d = x - mean[:, None, :]
    cov = np.einsum("bk,bki,bkj->bij", w, d, d)
    return mean, 0.5 * (cov + np.swapaxes(cov, -1, -2))


class ParticleFilter(Estimator):
    """The batched particle filter; a subclass sets the proposal by overriding :meth:`propose`.

    Args:
        model: the filter model, bound to a batch of B runs.
        particles: N per run.
        resampling: ``multinomial`` (roulette wheel), ``systematic``, ``stratified`` or ``residual``.
        schedule: ``every_step``, or ``ess`` (resample when ESS < ``ess_threshold``·N).
        ess_threshold: in (0, 1], used by ``schedule: ess``.
        estimate: ``weighted`` (mean and covariance of the weighted cloud before resampling) or
            ``resampled`` (of the cloud after resampling).
        roughening: Gordon et al.'s constant K (0: none).
        initial_cloud: ``sample`` (N draws from N(x0, P0)), ``point`` (every particle at x0) or
            ``uniform`` (every coordinate uniform on ``initial_range``, whatever x0: seed 001,
            §2.3 step 1, draws the particles on the state's value range, [0, 1] there).
        initial_range: ``[low, high]`` of ``initial_cloud: uniform``.
        weights: ``log`` (exact, log domain) or ``linear_floor`` (the UPF demo's likelihood
            plus ``weight_floor``; see the module docstring).
        weight_floor: the additive floor of ``linear_floor`` (> 0).
        vanished_weights: when every weight of a run vanishes, ``flag`` the run (it is parked)
            or fall back to ``uniform`` weights on the proposed cloud and carry on.
    """

    capabilities: ClassVar[frozenset[str]] = frozenset({"random", "cloud", "particle_smoothing"})

    def __init__(
        self,
        model: FilterModel,
        particles: int = 500,
        resampling: str = "systematic",
        schedule: str = "every_step",
        ess_threshold: float = 0.5,
        estimate: str = "weighted",
        roughening: float = 0.0,
        initial_cloud: str = "sample",
        initial_range: Sequence[float] = (0.0, 1.0),
        weights: str = "log",
        weight_floor: float = 1e-99,
        vanished_weights: str = "flag",
    ) -> None:
        super().__init__(model)
        check_scheme(resampling)
        one_of("schedule", schedule, SCHEDULES)
        one_of("estimate", estimate, ESTIMATES)
        one_of("initial_cloud", initial_cloud, INITIAL_CLOUDS)
        one_of("weights", weights, WEIGHTS)
        one_of("vanished_weights", vanished_weights, VANISHED_POLICIES)
        if (why := range_problem(initial_range)) is not None:
            raise ConfigError("initial_range", list(initial_range), why)
        if model.sensors or model.n_err != model.n:
            raise ConfigError(
                "model", model.name, "a model with vector states and one measurement (particle filters take no sensors)"
            )
        warm_up_particle_kernels()
        self.N = int(particles)
        self._log_uniform = np.log(np.full(1, 1.0 / self.N))[0]  # log(1/N) as np.log(w) gives it
        self.resampling, self.schedule, self.ess_threshold = resampling, schedule, float(ess_threshold)
        self.estimate, self.roughening, self.initial_cloud = estimate, float(roughening), initial_cloud
        self.initial_range = (float(initial_range[0]), float(initial_range[1]))
        self.weights, self.vanished_weights = weights, vanished_weights
        self.log_floor = float(np.log(weight_floor))
        self.particle_state: dict[str, np.ndarray] = {}

    # --- the hook subclasses override ---

    def propose(self, u_prev: np.ndarray, z: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """New particles (B, N, n) from ``self.x`` and the log proposal density at them (B, N);
        ``None`` when the proposal is the transition prior (bootstrap: the transition density
        cancels). A proposal may also replace entries of :attr:`particle_state`."""
        w = self.model.sample_process_noise_runs(self.rngs, (self.N,))
        return self.model.f_noise(self.x, w, u_prev), None

    # --- the filter ---

    def _per_run(self, draw) -> np.ndarray:
        """Stack ``draw(rng)`` over the runs' generators."""
        first = np.asarray(draw(self.rngs[0]))
        out = np.empty((len(self.rngs), *first.shape), dtype=first.dtype)
        out[0] = first
        for rng, row in zip(self.rngs[1:], out[1:], strict=True):
            row[...] = draw(rng)
        return out

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        B, n = x0.shape
        if len(getattr(self, "rngs", ())) != B:
            raise RuntimeError(f"{type(self).__name__} needs set_generators() with {B} generators before initialize")
        self._reset_failures(B)
        if self.initial_cloud == "sample":
            L0 = np.stack([psd_sqrt(P, "P0") for P in P0])  # P0 may be singular (a state known exactly)
            eps = standard_normals(self.rngs, (self.N, n))
            self.x = x0[:, None, :] + eps @ np.swapaxes(L0, -1, -2)
        elif self.initial_cloud == "uniform":
            low, high = self.initial_range
            self.x = low + (high - low) * self._per_run(lambda rng: rng.random((self.N, n)))
        else:
            self.x = np.repeat(x0[:, None, :], self.N, axis=1)
        self.logw = np.full((B, self.N), -np.log(self.N))
        self.log_increment = np.zeros((B, self.N))
        self._u_prev = np.zeros((B, self.model.nu))
        self.ess = np.full(B, float(self.N))
        self.ess_sum = np.zeros(B)
        self.resample_count = np.zeros(B, dtype=int)
        self.outside_support = np.zeros(B, dtype=int)
        self.floored_steps = np.zeros(B, dtype=int)
        self.vanished_steps = np.zeros(B, dtype=int)
        self.step = 0
        self._mean, self._cov = weighted_moments(self.x, np.exp(self.logw))
        self.particle_state = self.initial_particle_state(x0, P0)
        self._safe = {"x": self.x.copy(), **{key: arr.copy() for key, arr in self.particle_state.items()}}

    def diagnostics(self) -> dict[str, np.ndarray]:
        """Per run: mean ESS over the steps, resampling count, proposals outside the
        transition's support, steps at which no particle's likelihood exceeded ``weight_floor``
        (where ``weights: linear_floor`` lets the floor decide) and steps at which every weight
        vanished (the ``metrics.csv`` columns ``ess_mean``, ``resample_count``,
        ``outside_support``, ``floored_steps``, ``vanished_steps``)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            ess_mean = self.ess_sum / self.step
        return {
            "ess_mean": ess_mean,
            "resample_count": self.resample_count,
            "outside_support": self.outside_support,
            "floored_steps": self.floored_steps,
            "vanished_steps": self.vanished_steps,
        }

    def initial_particle_state(self, x0: np.ndarray, P0: np.ndarray) -> dict[str, np.ndarray]:
        """The per-particle arrays (B, N, ...) a proposal carries besides the particles, at the start
        (failed runs are parked on them); none by default."""
        return {}

    def predict(self, u: np.ndarray) -> None:
        """Record the input of the previous sample; the step itself runs in :meth:`update`."""
        self._u_prev = np.array(u, dtype=float, copy=True)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """The whole step (proposal, weights, estimate, resampling) with the primary measurement."""
        self.step += 1
        x_prev = self.x
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            x_new, log_q = self.propose(self._u_prev, z, u)
            residual = self.model.measurement(None).innovation(z[:, None, :], self.model.h(x_new, u))
            incr = self.model.measurement_noise_logpdf(residual)
            self.floored_steps += ~np.any(incr > self.log_floor, axis=1)
            if self.weights == "linear_floor":
                incr = np.logaddexp(incr, self.log_floor)
            if log_q is not None:
                log_trans = self.model.process_noise_logpdf(x_new - self.model.f(x_prev, self._u_prev))
                self.outside_support += np.sum(log_trans == -np.inf, axis=1)
                incr = incr + log_trans - log_q
        self.log_increment = incr
        self.x = x_new
        w, vanished, self.ess = normalised_weights(self.logw, incr)  # vanished rows: equal weights
        self.vanished_steps += vanished
        if vanished.any() and self.vanished_weights == "flag":
            self.flag(np.flatnonzero(vanished), f"all particle weights vanished at step {self.step}")
        self.ess_sum += self.ess
        if self.smoothing:
            self.smoother_cloud = ParticleCloud(x_new.copy(), w.copy(), self._u_prev.copy())
        if self.estimate == "weighted":
            self._mean, self._cov = weighted_moments(self.x, w)
        due = np.ones_like(vanished) if self.schedule == "every_step" else self.ess < self.ess_threshold * self.N
        runs = np.flatnonzero(due & ~self.failed)
        if runs.size:
            self.resample_runs(w, runs)
            w[runs] = 1.0 / self.N
            self.resample_count[runs] += 1
        if runs.size == w.shape[0]:
            self.logw = np.full_like(w, self._log_uniform)
        else:
            with np.errstate(divide="ignore"):
                self.logw = np.log(w)
        if self.estimate == "resampled":
            self._mean, self._cov = weighted_moments(self.x, w)
        self._park_failed()

    def resample_runs(self, w: np.ndarray, runs: np.ndarray) -> None:
        """Replace the clouds of ``runs`` by equally weighted ones drawn from weights ``w`` (B, N),
        then roughen them."""
        self.redraw(w[runs], runs)
        if self.roughening > 0:
            self._roughen(runs)

    def redraw(self, w: np.ndarray, runs: np.ndarray) -> None:
        """The resampling proper: new clouds for ``runs`` from their weights ``w`` (R, N), run
        ``runs[r]`` drawing from ``self.rngs[runs[r]]``, carrying :attr:`particle_state` (a filter
        with another resampling overrides this)."""
        idx = resample(self.resampling, w, self.rngs, runs)
        self.x = self._pick(self.x, runs, idx)
        self.carry(runs, idx)

    def _pick(self, arrays: np.ndarray, runs: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """``arrays`` (B, N, ...) with the particles of ``runs`` picked by ancestor indices ``idx``
        (R, N) (a new array when every run resamples, else updated in place), by the compiled
        gather for C-contiguous float arrays on the numba backend, else by :func:`gather_particles`."""
        kernels = particle_kernels()
        if kernels is not None and arrays.dtype == np.float64 and arrays.flags.c_contiguous:
            flat = arrays.reshape(*arrays.shape[:2], -1)
            out = np.empty_like(flat) if runs.size == arrays.shape[0] else flat
            kernels.gather_kernel(flat, runs, idx, out)
            return out.reshape(arrays.shape)
        if runs.size == arrays.shape[0]:
            return gather_particles(arrays, idx)
        arrays[runs] = gather_particles(arrays[runs], idx)
        return arrays

    def carry(self, runs: np.ndarray, idx: np.ndarray) -> None:
        """Pick the per-particle arrays of ``runs`` by ancestor indices ``idx`` (R, N)."""
        for key, arr in self.particle_state.items():
            self.particle_state[key] = self._pick(arr, runs, idx)

    def _roughen(self, runs: np.ndarray) -> None:
        x = self.x[runs]
        n = x.shape[-1]
        sigma = self.roughening * (x.max(axis=1) - x.min(axis=1)) * self.N ** (-1.0 / n)  # (R, n)
        eps = standard_normals(self.rngs, (self.N, n), runs)
        self.x[runs] = x + eps * sigma[:, None, :]

    def _park_failed(self) -> None:
        """Failed runs restart from their initial cloud, so they cannot disturb the others."""
        bad = ~(np.isfinite(self._mean).all(-1) & np.isfinite(self._cov).all((-2, -1)))
        if bad.any():
            self.flag(np.flatnonzero(bad), "non-finite particle mean or covariance")
        if self.failed.any():
            f = self.failed
            self.x[f] = self._safe["x"][f]
            for key, arr in self.particle_state.items():
                arr[f] = self._safe[key][f]
            self.logw[f] = -np.log(self.N)
            self._mean[f], self._cov[f] = weighted_moments(self.x[f], np.exp(self.logw[f]))

    @property
    def mean(self) -> np.ndarray:
        return self._mean

    @property
    def covariance(self) -> np.ndarray:
        return self._cov


KERNELS = ("exact", "fast")


@dataclass
class PFParams(ParticleParams):
    """Configuration of ``estimator=pf``: the bootstrap filter (see :class:`ParticleParams`), with
    ``kernel``: ``exact`` (every number bit for bit as the numpy references) or ``fast`` (the
    fused step of :mod:`quadest.numerics.fast_bootstrap`, within Monte Carlo error of exact)."""

    kind: str = "pf"
    kernel: str = "exact"

    @staticmethod
    def constraints(values: Mapping[str, Any], n: int) -> list[tuple[str, Any, str]]:
        """:meth:`ParticleParams.constraints`, ``kernel`` and what ``kernel: fast`` supports."""
        return particle_constraints(values) + fast_kernel_constraints(values)


def fast_kernel_constraints(values: Mapping[str, Any]) -> list[tuple[str, Any, str]]:
    """``(key, value, allowed)`` for a ``kernel`` outside :data:`KERNELS` and, with ``kernel:
    fast``, a resampling scheme it lacks (residual) or roughening (not fused)."""
    kernel = values.get("kernel", "exact")
    if kernel not in KERNELS:
        return [("kernel", kernel, f"one of {list(KERNELS)}")]
    if kernel != "fast":
        return []
    problems = []
    if values.get("resampling", "systematic") not in FAST_SCHEMES:
        problems.append(("resampling", values["resampling"], f"one of {list(FAST_SCHEMES)} with kernel: fast"))
    if values.get("roughening", 0.0) != 0.0:
        problems.append(("roughening", values["roughening"], "0 with kernel: fast"))
    return problems


class BootstrapPF(ParticleFilter):
    """Bootstrap / SIR particle filter (Gordon, Salmond & Smith 1993): the transition prior is the
    proposal, so the incremental weight is the likelihood ``p(y_k | x_k^i)``.

    Args:
        kernel: ``exact`` (default: :meth:`ParticleFilter.update`, every number as its numpy
            references give it) or ``fast`` (after the proposal, one fused pass per run of
            :func:`~quadest.numerics.fast_bootstrap.fast_bootstrap_step`: same filter, numbers
            within Monte Carlo error of ``exact``; resampling multinomial, systematic or
            stratified, no roughening).
        **options: the options of :class:`ParticleFilter`.
    """

    config_name = "pf"
    Params = PFParams

    def __init__(self, model: FilterModel, kernel: str = "exact", **options: Any) -> None:
        problems = fast_kernel_constraints({"kernel": kernel, **options})
        if problems:
            raise ConfigError(*problems[0])
        super().__init__(model, **options)
        self.kernel = kernel
        if kernel == "fast":
            self._whitening, self._log_norm = measurement_whitening(np.asarray(model.R, dtype=float))
            warm_up_fast_step()

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """The exact step, or with ``kernel: fast`` the proposal and the fused step."""
        if self.kernel == "exact":
            super().update(z, u, sensor)
            return
        self.step += 1
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            x_new, _ = self.propose(self._u_prev, z, u)
            hx = self.model.h(x_new, u)
            meas = self.model.measurement(None)
            if meas.residual is not None:  # the fused step forms z − hx: hand it z − r(z, hx)
                hx = z[:, None, :] - meas.innovation(z[:, None, :], hx)
        uniforms = draw_step_uniforms(self.resampling, self.rngs, self.N)
        out = fast_bootstrap_step(
            x_new,
            hx,
            z,
            self._whitening,
            self._log_norm,
            self.logw,
            uniforms,
            self.resampling,
            self.schedule == "every_step",
            self.ess_threshold,
            ~self.failed,
            self.estimate == "resampled",
            self.log_floor,
            self.weights == "linear_floor",
        )
        self.x, self.ess, self._mean, self._cov = out.x, out.ess, out.mean, out.cov
        self.floored_steps += out.floored
        self.vanished_steps += out.vanished
        if out.vanished.any() and self.vanished_weights == "flag":
            self.flag(np.flatnonzero(out.vanished), f"all particle weights vanished at step {self.step}")
        self.ess_sum += self.ess
        self.resample_count += out.resampled
        if self.smoothing:
            self.smoother_cloud = ParticleCloud(x_new.copy(), out.w.copy(), self._u_prev.copy())
        if out.resampled.all():
            self.logw = np.full_like(out.w, self._log_uniform)
        else:
            with np.errstate(divide="ignore"):
                self.logw = np.where(out.resampled[:, None], self._log_uniform, np.log(out.w))
        self._park_failed()
