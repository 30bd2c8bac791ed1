"""Baseline EKF: filterpy 2.0.0 ``ExtendedKalmanFilter``, one per run, with the mean propagated
through the nonlinear model and the model evaluated for the whole batch at once.

filterpy's EKF propagates ``x ← F x + B u`` (linear); :class:`_LinearisedEKF` overrides
``predict_x`` with ``x ← f(x, u)``, and ``F`` is the Jacobian at the posterior mean before each
``predict``. ``predict_update`` is not used (it linearises at the wrong point). Jacobians come
from the model (analytic for the quadrotor models).

Every filterpy step is unchanged; only *where* ``f``, ``F``, ``h`` and ``H`` are evaluated
differs. :class:`FilterpyEKF` evaluates them for its own run (four model calls of one point per
step), :class:`BatchedFilterpyEKF` (``estimator=ekf``) evaluates them once per step for every
run of the batch and hands each run's filterpy EKF its rows. A model call costs about the same
for one point as for a batch (numpy's per-call overhead dominates at this size), so that is
where the EKF's time went (``docs/benchmarks.md``). The numbers are the same either way.

On a model whose state is not a vector (``model=attitude``, ``model=ins``) filterpy's EKF carries
the error state about a reference point (:mod:`quadest.estimators.local_coordinates`): ``F`` and
``H`` are the model's error-state Jacobians ``F_err``/``H_err``, and each update's correction is
moved into the reference (the multiplicative EKF, Lefferts, Markley & Shuster 1982).

Smoothing (``smoother: fixed_interval | fixed_lag``, docs/smoothers.md): each run's filter keeps
the RTS smoother's step of its transition (Rauch, Tung & Striebel 1965) from the ``F`` and the
covariances filterpy used, by the same function as ``mekf``
(:func:`~quadest.estimators.smoothing.linearized_smoother_step`); on a manifold state the
correction is injected with ``⊞`` and, as the filter, without a reset Jacobian.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from quadest.estimators.base import PerRunAdapter, SingleRunEstimator
from quadest.estimators.local_coordinates import LocalCoordinates
from quadest.estimators.smoothing import SmootherStep, SmoothingForm, linearized_smoother_step
from quadest.models.base import FilterModel


@dataclass
class EKFParams:
    """Configuration of ``estimator=ekf`` (no tuning parameters)."""

    kind: str = "ekf"


class _LinearisedEKF(ExtendedKalmanFilter):
    """filterpy's EKF whose time update moves the mean to ``predicted`` = f(x, u)."""

    predicted: np.ndarray

    def predict_x(self, u=0) -> None:
        self.x = self.predicted


def _column_residual(residual: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Callable:
    """A measurement's ``residual`` of (..., m) rows as filterpy calls it, on (m, 1) columns."""
    return lambda z, hx: residual(z[:, 0], hx[:, 0])[:, None]


class FilterpyEKF(SingleRunEstimator):
    """filterpy's EKF with nonlinear propagation, on one run of a :class:`FilterModel`."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "smoothing"})

    def __init__(self, model: FilterModel) -> None:
        super().__init__(model)
        self.local = LocalCoordinates(model) if model.has_manifold_state else None
        self.kf = _LinearisedEKF(dim_x=model.n_err, dim_z=model.m)
        self.kf.Q = model.Q.copy()
        self.kf.R = model.R.copy()

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        if self.local is None:
            self.kf.x = np.array(x0, dtype=float).reshape(-1, 1)
        else:
            self.local.reset(x0)
            self.kf.x = np.zeros((self.model.n_err, 1))
        self.kf.P = np.array(P0, dtype=float)

    def predict(self, u: np.ndarray) -> None:
        x, u = self.mean[None, :], u[None, :]
        self.predict_linearised(self.model.F_err(x, u)[0], self.model.f(x[None], u)[0, 0])

    def predict_linearised(self, F: np.ndarray, fx: np.ndarray) -> None:
        """Time update given ``F`` (n_err, n_err) and ``f`` (n,) evaluated at the current mean."""
        self.kf.F = F
        if self.local is None:
            self.kf.predicted = fx.reshape(-1, 1)
        else:
            self.local.reset(fx)
            self.kf.predicted = np.zeros((self.model.n_err, 1))
        P = self.kf.P.copy() if self.smoothing else None
        self.kf.predict()
        if P is not None:
            factor = np.linalg.cholesky(self.kf.P)[None]  # a run whose P⁻ is not positive definite fails
            step = linearized_smoother_step(P[None], F[None], self.model.Q, factor, self.mean[None])
            self.smoother_step = SmootherStep(step.gain[0], step.predicted_mean[0], step.residual[0])

    def smoothing_form(self) -> SmoothingForm:
        """Covariance form; on a manifold state the model's ⊞/⊟ (no reset Jacobian, as the filter)."""
        if self.local is None:
            return SmoothingForm()
        return SmoothingForm(boxplus=self.model.boxplus, boxminus=self.model.boxminus)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """Update with the primary measurement or a named sensor (its ``h``, ``R`` and a
        central-difference Jacobian)."""
        x, u = self.mean[None, :], u[None, :]
        h = self.model.measurement(sensor).h(x[None], u)[0, 0]
        self.update_linearised(z, self.model.H_err(x, u, sensor)[0], h, sensor)

    def update_linearised(self, z: np.ndarray, H: np.ndarray, hx: np.ndarray, sensor: str | None = None) -> None:
        """Measurement update given ``H`` (m, n_err) and ``h`` (m,) evaluated at the current mean;
        the innovation is the measurement's residual (filterpy's ``residual`` argument)."""
        meas = self.model.measurement(sensor)
        self.kf.update(
            np.asarray(z, dtype=float).reshape(-1, 1),
            HJacobian=lambda _: H,
            Hx=lambda _: hx.reshape(-1, 1),
            R=meas.R,
            residual=np.subtract if meas.residual is None else _column_residual(meas.residual),
        )
        if self.local is not None:
            self.kf.x = self.local.inject(self.kf.x[:, 0])[:, None]

    @property
    def mean(self) -> np.ndarray:
        return self.kf.x[:, 0] if self.local is None else self.local.origin

    @property
    def covariance(self) -> np.ndarray:
        return self.kf.P

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self.kf.y[:, 0], np.linalg.cholesky(self.kf.S)


class BatchedFilterpyEKF(PerRunAdapter):
    """One :class:`FilterpyEKF` per run; ``f``, ``F``, ``h`` and ``H`` evaluated once per step for
    the whole batch at the runs' current means."""

    batched: ClassVar[bool] = True
    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "smoothing"})
    config_name = "ekf"
    Params = EKFParams

    def __init__(self, model: FilterModel) -> None:
        super().__init__(model, FilterpyEKF)

    def _points(self) -> np.ndarray | None:
        """The runs' current means, failed runs parked on a live run's mean (their rows are
        ignored; a NaN row would only raise floating-point warnings); ``None`` if none is live."""
        return None if self.failed.all() else self._park_failed_rows(self._mean)

    def predict(self, u: np.ndarray) -> None:
        x = self._points()
        if x is None:
            return
        F, fx = self.model.F_err(x, u), self.model.f(x[:, None], u)[:, 0]
        self._each(lambda i, filt: filt.predict_linearised(F[i], fx[i]))

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        x = self._points()
        if x is None:
            return
        H = self.model.H_err(x, u, sensor)
        hx = self.model.measurement(sensor).h(x[:, None], u)[:, 0]
        self._each(lambda i, filt: filt.update_linearised(z[i], H[i], hx[i], sensor))
