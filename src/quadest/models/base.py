"""The filter-model interface every estimator works through.

A filter model is the discrete-time system ``x_k = f(x_{k-1}, u_{k-1}) + v``,
``z_k = h(x_k, u_k) + n`` (thesis eqs 5.10–5.11, 5.32) with ``v ~ N(0, Q)``, ``n ~ N(0, R)``,
bound to one batch of ``B`` Monte Carlo runs: per-run parameters (for example the calibrated
sensor errors of each run) carry a leading batch axis.

Shapes (the contract every estimator relies on):

- ``f(x, u)``: ``x`` (B, K, n), ``u`` (B, nu) → (B, K, n). ``K`` is any number of points per run
  (2n+1 sigma points, one EKF mean, ...): all points of all runs go through in one call.
- ``h(x, u)``: ``x`` (B, K, n), ``u`` (B, nu) → (B, K, m).
- ``F(x, u)``: ``x`` (B, n) → (B, n, n), the Jacobian of ``f``; ``H(x, u)`` → (B, m, n).
  Models with analytic Jacobians override :meth:`FilterModel.F_analytic` and
  :meth:`FilterModel.H_analytic`; the others fall back to central differences.
- ``Q`` (n, n) and ``R`` (m, m) are shared by the runs of a batch.

Noise as distributions (for particle filters and non-Gaussian benchmarks): a model samples and
scores its own process and measurement noise with :meth:`FilterModel.sample_process_noise`,
:meth:`FilterModel.process_noise_logpdf` and their measurement twins. The defaults are the
zero-mean Gaussians ``N(0, Q)`` and ``N(0, R)``; a model with other noise overrides them (and its
``Q``, ``R`` stay the covariances the Gaussian filters assume).

Augmented sigma-point filters (van der Merwe 2004, "UKF2") put the noise into the sigma-point
state and call :meth:`FilterModel.f_noise` and :meth:`FilterModel.h_noise`. The defaults add the
noise (``f(x, u) + w``); a model whose noise is not additive overrides both, sets
``process_noise_dim``/``measurement_noise_dim`` and the covariances of ``w`` and ``v`` as ``Q``
and ``R``. A model that cannot take noise in the state sets ``supports_augmented = False``.

Some formulations carry *companion* quantities propagated outside the filter from its estimate,
as the thesis does with the Euler angles (§5.3.1: "integrate X_k to obtain position and
angles"). The runner keeps them per estimator and run with :meth:`companion_step` and feeds them
to ``f`` and ``h`` through :meth:`filter_input`.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from quadest.numerics.draws import all_runs, particle_kernels, standard_normals
from quadest.numerics.square_root import psd_sqrt


@dataclass(frozen=True)
class MeasurementModel:
    """A further sensor of a filter model: its own ``h`` (``x`` (B, K, n), ``u`` → (B, K, m)),
    noise covariance ``R`` and component names (Stone Soup's pattern: a measurement carries its
    own model, so many sensors at many rates are natural). Its samples and their availability
    come with the data (:class:`~quadest.montecarlo.data.SensorRecord`). ``groups`` names groups
    of its components whose NIS the tables judge apart (:mod:`quadest.metrics.groups`: GPS
    position and velocity); empty, the whole measurement is one group named after the sensor."""

    h: Callable[[np.ndarray, np.ndarray], np.ndarray]
    R: np.ndarray
    names: tuple[str, ...]
    residual: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    groups: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    @property
    def m(self) -> int:
        return self.R.shape[0]

    def innovation(self, z: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """``residual(z, ẑ)``: ``z − ẑ`` unless the measurement declares its own (a bearing
        wrapped to (−π, π], filterpy's ``residual_z``)."""
        return z - predicted if self.residual is None else self.residual(z, predicted)


UNIT_GROUPS = {"m/s": "velocities", "rad/s": "angle_rates", "rad": "angles", "m": "positions"}
"""The default state groups (:attr:`FilterModel.state_groups`): error states of one unit."""


class FilterModel(ABC):
    """Discrete-time model of a state-estimation problem, bound to a batch of runs.

    ``h``/``R`` are the primary measurement, available at every step. ``sensors`` names further
    measurement models; the runner updates with each when its sample is available.
    """

    name: str = "model"
    n: int
    m: int
    nu: int
    dt: float
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    measurement_names: tuple[str, ...]
    companion_names: tuple[str, ...] = ()
    companion_units: tuple[str, ...] = ()
    derived_error_names: tuple[str, ...] = ()
    derived_error_units: tuple[str, ...] = ()
    bias_states: tuple[str, ...] = ()
    extra_figures: tuple[str, ...] = ()
    Q: np.ndarray
    R: np.ndarray
    batch_size: int = 1
    fd_step: float = 1e-6
    supports_augmented: bool = True
    fused_unscented: bool = False  # f and h compiled for sigma points: the SR-UKF may take its fused steps
    sensors: Mapping[str, MeasurementModel] = MappingProxyType({})

    @abstractmethod
    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """State transition, ``x`` (B, K, n), ``u`` (B, nu) → (B, K, n)."""

    @abstractmethod
    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Measurement function, ``x`` (B, K, n), ``u`` (B, nu) → (B, K, m)."""

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        """Analytic Jacobian of ``f`` at ``x`` (B, n), or ``None`` when the model has none."""
        return None

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        """Analytic Jacobian of ``h`` at ``x`` (B, n), or ``None`` when the model has none."""
        return None

    def F(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobian of ``f`` (B, n, n): analytic when the model has it, else central differences."""
        J = self.F_analytic(x, u)
        return J if J is not None else self.jacobian_fd(self.f, x, u)

    def H(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobian of ``h`` (B, m, n): analytic when the model has it, else central differences."""
        J = self.H_analytic(x, u)
        return J if J is not None else self.jacobian_fd(self.h, x, u)

    def measurement(self, sensor: str | None = None) -> MeasurementModel:
        """The primary measurement (``sensor=None``: ``h``, ``R``) or ``sensors[sensor]``, as one
        :class:`MeasurementModel`, so a filter updates with either the same way."""
        if sensor is None:
            residual = (
                None
                if type(self).measurement_residual is FilterModel.measurement_residual
                else self.measurement_residual
            )
            return MeasurementModel(self.h, self.R, tuple(self.measurement_names), residual)
        return self.sensors[sensor]

    def measurement_residual(self, z: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """``z ⊟ ẑ`` of the primary measurement (..., m): ``z − ẑ`` unless a model overrides it
        (a bearing: the difference wrapped to (−π, π]). The filters of
        :mod:`quadest.estimators.gaussian_filter` condition on it."""
        return z - predicted

    def measurement_jacobian(self, sensor: str | None, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobian (B, m, n) of the primary measurement (:meth:`H`) or of a further sensor
        (central differences) at ``x`` (B, n)."""
        return self.H(x, u) if sensor is None else self.jacobian_fd(self.sensors[sensor].h, x, u)

    def F_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobians of ``f`` at ``K`` points per run, ``x`` (B, K, n) → (B, K, n, n) (for example
        one per particle). Central differences in one model call unless a model overrides it."""
        return self.jacobian_fd_points(self.f, x, u)

    def H_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobians of ``h`` at ``K`` points per run, ``x`` (B, K, n) → (B, K, m, n)."""
        return self.jacobian_fd_points(self.h, x, u)

    def jacobian_fd_points(self, fun, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Central-difference Jacobians of ``fun`` at ``x`` (B, K, n): all 2nK points in one call."""
        B, K, n = x.shape
        step = self.fd_step * np.maximum(1.0, np.abs(x))  # (B, K, n)
        E = np.eye(n)[None, None] * step[:, :, None, :]  # (B, K, n, n): row j moves coordinate j
        pts = np.concatenate([x[:, :, None, :] + E, x[:, :, None, :] - E], axis=2).reshape(B, K * 2 * n, n)
        y = fun(pts, u).reshape(B, K, 2 * n, -1)
        return np.swapaxes((y[:, :, :n] - y[:, :, n:]) / (2.0 * step[..., None]), -1, -2)

    def jacobian_fd(self, fun, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Central-difference Jacobian of ``fun`` at ``x`` (B, n): all 2n points in one call."""
        n = x.shape[-1]
        step = self.fd_step * np.maximum(1.0, np.abs(x))
        E = np.eye(n)[None] * step[:, None, :]
        pts = np.concatenate([x[:, None, :] + E, x[:, None, :] - E], axis=1)
        y = fun(pts, u)
        return np.swapaxes((y[:, :n] - y[:, n:]) / (2.0 * step[:, :, None]), -1, -2)

    # --- states that are not vectors (error-state dimension, boxplus and boxminus) ---

    @property
    def n_err(self) -> int:
        """Dimension of the error state, the covariance and the NEES (``n`` for vector states)."""
        return self.n

    @property
    def error_names(self) -> tuple[str, ...]:
        """Names of the error-state components (the RMSE and NEES rows); the state names for
        vector states."""
        return self.state_names

    @property
    def state_groups(self) -> dict[str, tuple[str, ...]]:
        """Named groups of error states (``error_names``) that the tables judge together: the NEES
        per group (:mod:`quadest.metrics.groups`) and the sweep's versus-best scores. By default
        the error states that share a unit, named by :data:`UNIT_GROUPS` (``states`` for the
        others); a model overrides it where its units do not say what belongs together."""
        groups: dict[str, tuple[str, ...]] = {}
        for name, unit in zip(self.error_names, self.error_units, strict=True):
            group = UNIT_GROUPS.get(unit, "states")
            groups[group] = (*groups.get(group, ()), name)
        return groups

    @property
    def measurement_groups(self) -> dict[str, tuple[str, ...]]:
        """Named groups of the primary measurement's components (``measurement_names``) whose NIS
        the tables judge apart, each against its own χ² band (:mod:`quadest.metrics.groups`). By
        default one group, ``measurement``, the whole measurement (none when ``m = 0``); a model
        overrides it where its measurement stacks several sensors (the MIMU's accelerometer and
        gyro). Further sensors declare theirs in :attr:`MeasurementModel.groups`."""
        return {"measurement": tuple(self.measurement_names)} if self.m else {}

    @property
    def error_units(self) -> tuple[str, ...]:
        return self.state_units

    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``x ⊞ dx``: move states ``x`` (..., n) by error-state vectors ``dx`` (..., n_err)
        (filterpy's ``state_add``). Plain addition unless a model overrides it."""
        return x + dx

    def boxminus(self, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``y ⊟ x``: the error-state vector (..., n_err) from ``x`` to ``y`` (filterpy's
        ``residual_x``). Plain subtraction unless a model overrides it."""
        return y - x

    # --- error-state Jacobians (multiplicative / error-state EKF; Solà 2017 §5, §7) ---

    @property
    def has_manifold_state(self) -> bool:
        """Whether the state is not a vector (the model overrides :meth:`boxplus`)."""
        return type(self).boxplus is not FilterModel.boxplus

    def F_err_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        """Analytic error-state transition Jacobian (B, n_err, n_err) at ``x`` (B, n), or ``None``."""
        return None

    def H_err_analytic(self, x: np.ndarray, u: np.ndarray, sensor: str | None = None) -> np.ndarray | None:
        """Analytic error-state measurement Jacobian (B, m, n_err) at ``x`` (B, n), or ``None``."""
        return None

    def F_err(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``∂[f(x ⊞ δ, u) ⊟ f(x, u)]/∂δ`` at ``δ = 0`` (B, n_err, n_err) (Solà 2017 eq. 269's
        ``F_x``): analytic when the model has it; for vector states :meth:`F`; otherwise central
        differences on the manifold."""
        J = self.F_err_analytic(x, u)
        if J is not None:
            return J
        if not self.has_manifold_state:
            return self.F(x, u)
        return self.manifold_jacobian_fd(self.f, x, u, state_valued=True)

    def H_err(self, x: np.ndarray, u: np.ndarray, sensor: str | None = None) -> np.ndarray:
        """``∂h(x ⊞ δ, u)/∂δ`` at ``δ = 0`` (B, m, n_err) of the primary measurement or of
        ``sensors[sensor]`` (Solà 2017 eq. 279, ``H = H_x X_δx``): analytic when the model has
        it; for vector states :meth:`measurement_jacobian`; otherwise central differences on the
        manifold."""
        J = self.H_err_analytic(x, u, sensor)
        if J is not None:
            return J
        if not self.has_manifold_state:
            return self.measurement_jacobian(sensor, x, u)
        return self.manifold_jacobian_fd(self.measurement(sensor).h, x, u, state_valued=False)

    def reset_jacobian(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """``G = ∂[(x ⊞ (dx + e)) ⊟ (x ⊞ dx)]/∂e`` at ``e = 0`` (B, n_err, n_err): the error state
        after the correction ``dx`` is injected into the mean, ``P ← G P Gᵀ`` (Solà 2017 §7.2,
        eqs. 284–287). The identity for vector states; central differences otherwise."""
        B, ne = dx.shape
        if not self.has_manifold_state:
            return np.broadcast_to(np.eye(ne), (B, ne, ne)).copy()
        E = self.fd_step * np.eye(ne)
        moved = self.boxplus(x, dx)
        plus = self.boxplus(np.repeat(x[:, None], ne, axis=1), dx[:, None] + E)
        minus = self.boxplus(np.repeat(x[:, None], ne, axis=1), dx[:, None] - E)
        d = self.boxminus(plus, moved[:, None]) - self.boxminus(minus, moved[:, None])
        return np.swapaxes(d / (2.0 * self.fd_step), -1, -2)

    def manifold_jacobian_fd(self, fun, x: np.ndarray, u: np.ndarray, state_valued: bool) -> np.ndarray:
        """Central differences of ``fun`` along the error state: points ``x ⊞ (±h e_j)``, and the
        outputs differenced with :meth:`boxminus` about ``fun(x)`` when ``state_valued`` (``f``),
        plainly otherwise (``h``). ``h = fd_step`` (the error state is centred at zero)."""
        ne = self.n_err
        E = self.fd_step * np.eye(ne)
        pts = self.boxplus(np.repeat(x[:, None], 2 * ne, axis=1), np.concatenate([E, -E])[None])
        y = fun(np.concatenate([pts, x[:, None]], axis=1), u)
        if state_valued:
            d = self.boxminus(y[:, : 2 * ne], y[:, 2 * ne :])
        else:
            d = y[:, : 2 * ne]
        return np.swapaxes((d[:, :ne] - d[:, ne:]) / (2.0 * self.fd_step), -1, -2)

    # --- noise: distributions and the augmented (noise-in-the-state) form ---

    @property
    def process_noise_dim(self) -> int:
        """Dimension of the process noise ``w`` (``Q`` is its covariance)."""
        return self.Q.shape[0]

    @property
    def measurement_noise_dim(self) -> int:
        """Dimension of the measurement noise ``v`` (``R`` is its covariance)."""
        return self.R.shape[0]

    def f_noise(self, x: np.ndarray, w: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Transition with explicit noise ``w`` (B, K, q): ``f(x, u) + w`` unless overridden."""
        return self.f(x, u) + w

    def h_noise(self, x: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Measurement with explicit noise ``v`` (B, K, r): ``h(x, u) + v`` unless overridden."""
        return self.h(x, u) + v

    def _noise_factor(self, C: np.ndarray) -> np.ndarray:
        """``psd_sqrt(C)``, computed once per matrix value (sampling calls it every step)."""
        cache = self.__dict__.setdefault("_noise_factors", {})
        key = C.tobytes()
        if key not in cache:
            cache[key] = psd_sqrt(C, "noise covariance")
        return cache[key]

    def _diagonal_scale(self, C: np.ndarray) -> np.ndarray | None:
        """``√diag(C)`` (the diagonal of its Cholesky factor, exactly) when ``C`` is diagonal with a
        positive diagonal, else ``None``; computed once per matrix value."""
        cache = self.__dict__.setdefault("_diagonal_scales", {})
        key = C.tobytes()
        if key not in cache:
            diagonal = np.diagonal(C)
            cache[key] = np.sqrt(diagonal) if np.array_equal(C, np.diag(diagonal)) and np.all(diagonal > 0) else None
        return cache[key]

    def _gaussian_draws(self, rng: np.random.Generator, size: tuple[int, ...], C: np.ndarray) -> np.ndarray:
        """``(*size, q)`` draws of N(0, C): standard normals times the factor's transpose; for a
        diagonal ``C`` one product per value by ``√diag(C)`` (the matrix product's values exactly:
        its other terms are exact zeros)."""
        e = rng.standard_normal((*size, C.shape[0]))
        scale = self._diagonal_scale(C)
        if scale is None:
            return e @ self._noise_factor(C).T
        e *= scale
        return e

    def sample_process_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        """Draws of the process noise, shape ``(*size, q)``; N(0, Q) unless overridden."""
        return self._gaussian_draws(rng, size, self.Q)

    def sample_process_noise_runs(
        self, rngs: Sequence[np.random.Generator], size: tuple[int, ...], runs: np.ndarray | None = None
    ) -> np.ndarray:
        """Process-noise draws of many runs at once, ``(R, *size, q)``: row ``r`` is
        ``sample_process_noise(rngs[runs[r]], size)`` exactly (``runs``: all when ``None``). The
        Gaussian default draws the whole batch's normals in one call
        (:func:`~quadest.numerics.draws.standard_normals`); a model that overrides
        :meth:`sample_process_noise` is called once per run."""
        if type(self).sample_process_noise is not FilterModel.sample_process_noise:
            return np.stack([self.sample_process_noise(rngs[b], size) for b in all_runs(rngs, runs)])
        e = standard_normals(rngs, (*size, self.Q.shape[0]), runs)
        scale = self._diagonal_scale(self.Q)
        if scale is not None:
            e *= scale
            return e
        factor = self._noise_factor(self.Q).T
        for row in e:
            row[...] = row @ factor  # one product per run, as the per-run draw computes it
        return e

    def process_noise_logpdf(self, w: np.ndarray) -> np.ndarray:
        """Log-density of process-noise values ``w`` (..., q) → (...); N(0, Q) unless overridden."""
        return _gaussian_logpdf(w, self.Q, self._diagonal_scale(self.Q))

    def sample_measurement_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        """Draws of the measurement noise, shape ``(*size, r)``; N(0, R) unless overridden."""
        return self._gaussian_draws(rng, size, self.R)

    def measurement_noise_logpdf(self, v: np.ndarray) -> np.ndarray:
        """Log-density of measurement-noise values ``v`` (..., r) → (...); N(0, R) unless overridden."""
        return _gaussian_logpdf(v, self.R, self._diagonal_scale(self.R))

    # --- companion quantities (thesis: angles and positions integrated outside the filter) ---

    def filter_input(self, u: np.ndarray, companion: np.ndarray) -> np.ndarray:
        """The input ``f`` and ``h`` receive: the measured input plus any companion values."""
        return u

    def companion_step(self, companion: np.ndarray, x_post: np.ndarray) -> np.ndarray:
        """Advance the companion values one sample from the posterior estimate ``x_post`` (B, n)."""
        return companion

    # --- what the job reports besides the error state ---

    def derived_errors(self, estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
        """Errors of quantities derived from the state (``derived_error_names``, in
        ``derived_error_units``; e.g. roll, pitch, yaw in degrees), ``estimate`` and ``truth``
        (B, n) → (B, d). The runner accumulates their squares per run like the state errors (rows
        of quantity ``derived`` in the metrics tables). None unless a model declares them.

        ``bias_states`` names the error states that are sensor biases (the job reports their
        convergence time, :func:`quadest.evaluation.metrics.convergence_table`); ``extra_figures`` names
        figures of :data:`quadest.evaluation.plotting.EXTRA_FIGURES` the job draws for this model."""
        return np.zeros((*estimate.shape[:-1], 0))

    # --- batches ---

    def _per_run_arrays(self) -> tuple[str, ...]:
        """Names of attributes that carry a leading batch axis."""
        return ()

    def select(self, runs: int | slice | np.ndarray) -> FilterModel:
        """A copy of the model bound to a subset of the batch (an int gives a batch of one)."""
        idx = slice(runs, runs + 1) if isinstance(runs, int | np.integer) else runs
        other = copy.copy(self)
        for name in self._per_run_arrays():
            setattr(other, name, getattr(self, name)[idx])
        other.batch_size = len(np.arange(self.batch_size)[idx])
        return other


def _gaussian_logpdf(e: np.ndarray, C: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """``log N(e; 0, C)`` for a positive-definite ``C``, over the last axis of ``e``.

    With ``scale = √diag(C)`` for a diagonal ``C``, the whitening is a product by its reciprocals
    instead of a Cholesky factorisation and a triangular solve: the arithmetic numpy's OpenBLAS
    solve does for a diagonal factor, without the solve's per-call cost, which dominated a
    particle filter's weighting. The values equal the general path's for up to 4 dimensions and
    agree to about one ulp above (the squares are summed in another order)."""
    if scale is not None:
        log_det = np.sum(np.log(scale))
        kernels = particle_kernels()
        if kernels is not None and e.dtype == np.float64:
            out = np.empty(e.shape[:-1])
            flat = np.ascontiguousarray(e).reshape(-1, e.shape[-1])
            kernels.gaussian_logpdf_diagonal_kernel(
                flat, 1.0 / scale, C.shape[0] * np.log(2.0 * np.pi), log_det, out.reshape(-1)
            )
            return out
        maha = np.sum((e * (1.0 / scale)) ** 2, axis=-1)
    else:
        L = np.linalg.cholesky(C)
        white = np.linalg.solve(L, np.moveaxis(e, -1, 0).reshape(C.shape[0], -1))
        maha = np.sum(white**2, axis=0).reshape(e.shape[:-1])
        log_det = np.sum(np.log(np.diag(L)))
    return -0.5 * (maha + C.shape[0] * np.log(2.0 * np.pi)) - log_det
