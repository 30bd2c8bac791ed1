"""Baseline EKF: filterpy 2.0.0 ``ExtendedKalmanFilter``, subclassed so that the mean propagates
through the nonlinear model.

filterpy's EKF propagates ``x ← F x + B u`` (linear); :class:`_NonlinearEKF` overrides
``predict_x`` with ``x ← f(x, u)`` and the wrapper sets ``F`` to the Jacobian at the posterior
mean before each ``predict``. ``predict_update`` is not used (it linearises at the wrong point).
Jacobians come from the model (analytic for the quadrotor models).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from quadest.estimators.base import SingleRunEstimator
from quadest.models.base import FilterModel


@dataclass
class EKFParams:
    """Configuration of ``estimator=ekf`` (no tuning parameters)."""

    kind: str = "ekf"


class _NonlinearEKF(ExtendedKalmanFilter):
    def __init__(self, model: FilterModel) -> None:
        super().__init__(dim_x=model.n, dim_z=model.m)
        self.model = model

    def predict_x(self, u=0) -> None:
        self.x = self.model.f(self.x.T[None], u[None, :])[0].T


class FilterpyEKF(SingleRunEstimator):
    """filterpy's EKF with nonlinear propagation, on one run of a :class:`FilterModel`."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation"})
    config_name = "ekf"
    Params = EKFParams

    def __init__(self, model: FilterModel) -> None:
        super().__init__(model)
        self.kf = _NonlinearEKF(model)
        self.kf.Q = model.Q.copy()
        self.kf.R = model.R.copy()

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self.kf.x = np.array(x0, dtype=float).reshape(-1, 1)
        self.kf.P = np.array(P0, dtype=float)

    def predict(self, u: np.ndarray) -> None:
        self.kf.F = self.model.F(self.kf.x.T, u[None, :])[0]
        self.kf.predict(u=u)

    def update(self, z: np.ndarray, u: np.ndarray) -> None:
        self.kf.update(
            np.asarray(z, dtype=float).reshape(-1, 1),
            HJacobian=lambda x: self.model.H(x.T, u[None, :])[0],
            Hx=lambda x: self.model.h(x.T[None], u[None, :])[0].T,
        )

    @property
    def mean(self) -> np.ndarray:
        return self.kf.x[:, 0]

    @property
    def covariance(self) -> np.ndarray:
        return self.kf.P

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self.kf.y[:, 0], self.kf.S
