"""Baseline UKF: filterpy 2.0.0 ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints``.

Same α, β, κ keys as the SR-UKF. filterpy 2.0 redraws the sigma points after the time update
and takes the Cholesky factor whose rows are the columns of the lower factor, so with equal
parameters it is the same filter as the SR-UKF in exact arithmetic (docs/srukf.md,
docs/sources.md). It works on one run; the framework's :class:`PerRunAdapter` loops it over the batch.

filterpy calls ``fx`` and ``hx`` once per sigma point. :class:`_PointBatchedUKF` keeps filterpy's
UKF equations untouched and only evaluates all 2n+1 points in one vectorised model call: the time
update overrides filterpy's ``compute_process_sigmas`` hook, and the measurement update hands
filterpy an ``hx`` that returns the rows of one precomputed ``h`` call in filterpy's call order.
The numbers are the same as with per-point calls; ``vectorize_points=False`` gives the plain
per-point use (the benchmark times both).

:class:`BatchedFilterpyUKF` (``estimator=ukf``) goes one step further, as the EKF baseline does
(:mod:`quadest.estimators.filterpy_ekf`): still one filterpy UKF per run, but the sigma points of
every run of the batch pass through ``f`` and through ``h`` in one model call each per step. A
model call costs about the same for one run's 2n+1 points as for the whole batch (numpy's
per-call overhead dominates), so this removes most of the model's share of the step
(``docs/benchmarks.md``).

On a model whose state is not a vector (``model=attitude``, ``model=ins``) the UKF's state is the
error about a reference point (:mod:`quadest.estimators.local_coordinates`; USQUE, Crassidis &
Markley 2003): its sigma points are errors, the model functions see ``reference ⊞ error``, and
each update's mean error is moved into the reference.

Smoothing (``smoother: fixed_interval | fixed_lag``, docs/smoothers.md): each run's filter keeps
the unscented RTS smoother's step (Särkkä 2008) from the sigma points filterpy propagated, by the
same functions as the sigma-point family (:func:`~quadest.estimators.smoothing.sigma_point_smoother_gain`
with the UT rule of the same α, β, κ); so it equals filterpy's own ``rts_smoother`` given the same
filtered sequence. On a manifold state the deviations are the local errors and the correction is
injected with ``⊞`` (no reset Jacobian, as the filter).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

from quadest.estimators.base import PerRunAdapter, SingleRunEstimator
from quadest.estimators.gaussian_steps import sigma_point_covariance
from quadest.estimators.local_coordinates import LocalCoordinates
from quadest.estimators.params import ranged, unscented_constraints
from quadest.estimators.smoothing import SmootherStep, SmoothingForm, sigma_point_smoother_gain
from quadest.models.base import FilterModel
from quadest.numerics import ut_weights
from quadest.numerics.rules import UnscentedRule


@dataclass
class UKFParams:
    """Configuration of ``estimator=ukf``: the UT parameters of ``srukf`` (thesis eqs 5.2–5.6)."""

    kind: str = "ukf"
    alpha: float = ranged(0.5, "spread of the sigma points; typically 1e-4 <= alpha <= 1", gt=0.0)
    beta: float = ranged(2.0, "prior knowledge of the distribution; 2 is optimal for a Gaussian")
    kappa: float = ranged(0.0, "secondary scaling; usually 0 for state estimation")

    constraints = staticmethod(unscented_constraints)


class _PointBatchedUKF(UnscentedKalmanFilter):
    """filterpy's UKF with the sigma points of each step evaluated in one model call of the
    vectorised ``f_points``/``h_points`` (points (1, P, n), input (1, m_u))."""

    def __init__(self, f_points: Callable, h_points: Callable, **kwargs) -> None:
        super().__init__(**kwargs)
        self.f_points, self.h_points = f_points, h_points
        self.propagated: np.ndarray | None = None
        self.propagated_points: np.ndarray | None = None

    def compute_process_sigmas(self, dt, fx=None, **fx_args) -> None:
        """``self.sigmas_f``: the sigma points of (x, P) through ``f``, or ``propagated`` if given
        (those same points, evaluated by the caller; used once)."""
        if self.propagated is not None:
            self.sigmas_f, self.propagated = self.propagated, None
        else:
            sigmas = self.points_fn.sigma_points(self.x, self.P)
            self.sigmas_f = self.f_points(sigmas[None], fx_args["u"][None, :])[0]
        self.propagated_points = self.sigmas_f  # filterpy redraws sigmas_f from (x⁻, P⁻) after this

    def update(self, z, R=None, UT=None, hx=None, h_points=None, h_values=None, **hx_args) -> None:
        """``h_points`` (default the primary measurement's) is the vectorised measurement function;
        ``h_values`` (P, m), if given, are its values at ``self.sigmas_f``, evaluated by the caller."""
        if h_values is None:
            h = self.h_points if h_points is None else h_points
            h_values = h(self.sigmas_f[None], hx_args["u"][None, :])[0]
        rows = iter(h_values)
        super().update(z, R=R, UT=UT, hx=lambda x, u: next(rows), **hx_args)


def _residual_mean(residual: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Callable:
    """filterpy's ``z_mean`` (sigma points (P, m), weights (P,)) for a measurement residual ``r``:
    ``Y_0 + Σ wm_i r(Y_i, Y_0)``."""
    return lambda Y, wm: Y[0] + wm[1:] @ residual(Y[1:], Y[0])


class FilterpyUKF(SingleRunEstimator):
    """filterpy's UKF on one run of a :class:`FilterModel`."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "smoothing"})

    def __init__(
        self,
        model: FilterModel,
        alpha: float = 0.5,
        beta: float = 2.0,
        kappa: float = 0.0,
        vectorize_points: bool = True,
    ) -> None:
        super().__init__(model)
        n = model.n_err
        ut_weights(n, alpha, beta, kappa)  # the same checks as the SR-UKF: α > 0, n + λ > 0
        self.rule = UnscentedRule(alpha, beta, kappa)  # filterpy's weights, for the smoother step
        self.local = LocalCoordinates(model) if model.has_manifold_state else None
        self._f_points = model.f if self.local is None else self.local.f
        self._h_points = self._sensor_points(model.h)
        points = MerweScaledSigmaPoints(n, alpha=alpha, beta=beta, kappa=kappa)
        kwargs = dict(dim_x=n, dim_z=model.m, dt=model.dt, hx=self._hx, fx=self._fx, points=points)
        self.kf = (
            _PointBatchedUKF(self._f_points, self._h_points, **kwargs)
            if vectorize_points
            else UnscentedKalmanFilter(**kwargs)
        )
        self.kf.Q = model.Q.copy()
        self.kf.R = model.R.copy()

    def _sensor_points(self, h: Callable) -> Callable:
        """A measurement function of the model's points as a function of the filter's points."""
        return h if self.local is None else self.local.measurement(h)

    def _fx(self, x: np.ndarray, dt: float, u: np.ndarray) -> np.ndarray:
        return self._f_points(x[None, None, :], u[None, :])[0, 0]

    def _hx(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self._h_points(x[None, None, :], u[None, :])[0, 0]

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        if self.local is None:
            self.kf.x = np.array(x0, dtype=float)
        else:
            self.local.reset(x0)
            self.kf.x = np.zeros(self.model.n_err)
        self.kf.P = np.array(P0, dtype=float)

    def predict(self, u: np.ndarray) -> None:
        before = (self.kf.x.copy(), self.process_points()) if self.smoothing else None
        if self.local is None:
            self.kf.predict(u=u)
        else:
            self.local.advance(u)
            self.kf.predict(u=u)
            self.local.settle()
        self._record_smoother_step(before)

    def process_points(self) -> np.ndarray:
        """The sigma points (2n+1, n) the next time update propagates (filterpy's own rule)."""
        return self.kf.points_fn.sigma_points(self.kf.x, self.kf.P)

    def predict_propagated(self, sigmas_f: np.ndarray, u: np.ndarray, points: np.ndarray | None = None) -> None:
        """Time update of a vector state given :meth:`process_points` (``points``; with smoothing
        on they make its step) through ``f`` (2n+1, n)."""
        before = (self.kf.x.copy(), points) if self.smoothing else None
        self.kf.propagated = sigmas_f
        self.kf.predict(u=u)
        self._record_smoother_step(before)

    def _record_smoother_step(self, before: tuple[np.ndarray, np.ndarray] | None) -> None:
        """The step of this predict from the filtered mean and sigma points before it (``before``,
        in the filter's coordinates) and the same points through ``f`` (about ``x⁻``): ``G`` and the
        residual, the rule's spread of ``DX − G D⁻`` plus ``G Q Gᵀ``."""
        if before is None:
            return
        if not isinstance(self.kf, _PointBatchedUKF):
            raise ValueError("smoothing needs the propagated sigma points: use vectorize_points=True")
        x, points = before
        n = self.model.n_err
        DX, D = (points - x)[None], (self.kf.propagated_points - self.kf.x)[None]
        G, E = sigma_point_smoother_gain(self.rule, DX, D, n, np.linalg.cholesky(self.kf.P)[None])
        residual = sigma_point_covariance(self.rule, E, n, G @ self.model.Q @ np.swapaxes(G, -1, -2))
        self.smoother_step = SmootherStep(G[0], self.mean.copy(), residual[0])

    def smoothing_form(self) -> SmoothingForm:
        """Covariance form; on a manifold state the model's ⊞/⊟ (no reset Jacobian, as the filter)."""
        if self.local is None:
            return SmoothingForm()
        return SmoothingForm(boxplus=self.model.boxplus, boxminus=self.model.boxminus)

    def _use_residual(self, sensor: str | None) -> None:
        """filterpy's ``residual_z`` and ``z_mean`` for this measurement: ``np.subtract`` and the
        weighted sum, or the measurement's residual ``r`` and the mean ``Y_0 + Σ wm_i r(Y_i, Y_0)``
        (points on both sides of a wrap average to the right angle)."""
        residual = self.model.measurement(sensor).residual
        if residual is None:
            self.kf.residual_z, self.kf.z_mean = np.subtract, None
        else:
            self.kf.residual_z, self.kf.z_mean = residual, _residual_mean(residual)

    def update_evaluated(self, z: np.ndarray, h_values: np.ndarray, u: np.ndarray) -> None:
        """Primary update of a vector state given ``h`` at the prior sigma points ``kf.sigmas_f``."""
        self._use_residual(None)
        self.kf.update(z, u=u, h_values=h_values)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """Update with the primary measurement or a named sensor (its ``h``, ``R`` and residual)."""
        self._use_residual(sensor)
        if sensor is None:
            self.kf.update(z, u=u)
        else:
            meas = self.model.measurement(sensor)
            h_points = self._sensor_points(meas.h)
            # filterpy updates with the points of its last predict; a further sensor in the same step
            # must see points of the state after the previous update (no time passes between them).
            self.kf.sigmas_f = self.kf.points_fn.sigma_points(self.kf.x, self.kf.P)
            if isinstance(self.kf, _PointBatchedUKF):
                self.kf.update(z, R=meas.R, h_points=h_points, u=u)
            else:
                self.kf.update(z, R=meas.R, hx=lambda x, u: h_points(x[None, None, :], u[None, :])[0, 0], u=u)
        if self.local is not None:
            self.kf.x = self.local.inject(self.kf.x)

    @property
    def mean(self) -> np.ndarray:
        return self.kf.x if self.local is None else self.local.state(self.kf.x)

    @property
    def covariance(self) -> np.ndarray:
        return self.kf.P

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self.kf.y, np.linalg.cholesky(self.kf.S)


class BatchedFilterpyUKF(PerRunAdapter):
    """One :class:`FilterpyUKF` per run; on a vector state, the sigma points of all runs go
    through ``f`` (time update) and ``h`` (primary measurement update) in one model call each.
    Manifold states and named sensors take the per-run path."""

    batched: ClassVar[bool] = True
    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "smoothing"})
    config_name = "ukf"
    Params = UKFParams

    def __init__(self, model: FilterModel, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0) -> None:
        super().__init__(model, FilterpyUKF, alpha=alpha, beta=beta, kappa=kappa)
        self._lockstep = not model.has_manifold_state

    def _stack(self, points_of: Callable[[FilterpyUKF], np.ndarray]) -> np.ndarray | None:
        """``points_of(filter)`` of every live run stacked (B, P, n), failed runs parked on a live
        run's points; a run whose points cannot be formed (filterpy's Cholesky fails) is flagged."""
        rows: dict[int, np.ndarray] = {}
        for i, filt in enumerate(self.filters):
            if self.failed[i]:
                continue
            try:
                rows[i] = points_of(filt)
            except Exception as exc:  # a run's failure marks that run, never the batch
                self.flag(i, f"{type(exc).__name__}: {exc}")
        if not rows:
            return None
        stacked = np.empty((len(self.filters), *next(iter(rows.values())).shape))
        for i, points in rows.items():
            stacked[i] = points
        return self._park_failed_rows(stacked)

    def predict(self, u: np.ndarray) -> None:
        if not self._lockstep:
            super().predict(u)
            return
        points = self._stack(FilterpyUKF.process_points)
        if points is not None:
            fx = self.model.f(points, u)
            self._each(lambda i, filt: filt.predict_propagated(fx[i], u[i], points[i]))

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        if not self._lockstep or sensor is not None:
            super().update(z, u, sensor)
            return
        points = self._stack(lambda filt: filt.kf.sigmas_f)
        if points is not None:
            hx = self.model.h(points, u)
            self._each(lambda i, filt: filt.update_evaluated(z[i], hx[i], u[i]))
