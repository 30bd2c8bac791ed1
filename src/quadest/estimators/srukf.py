"""Square-root unscented Kalman filter of the thesis (seed 000, chapter 5, eqs 5.12–5.29),
batched over Monte Carlo runs.

State per run: the mean ``x`` (n,) and a lower-triangular factor ``S`` (n, n) with ``P = S Sᵀ``.
The whole batch advances in one call per step: sigma points (B, 2n+1, n) go through the model's
``f`` and ``h`` at once; ``qr`` and ``cholupdate`` are batched (:mod:`quadest.numerics`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadest.errors import DowndateError
from quadest.estimators.base import Estimator
from quadest.models.base import FilterModel
from quadest.numerics import (
    cholupdate,
    kalman_gain,
    qr_factor,
    sigma_points,
    ut_weights,
    weighted_mean,
)


@dataclass
class SRUKFParams:
    """Configuration of ``estimator=srukf``: the UT scaling parameters (eqs 5.2–5.6)."""

    kind: str = "srukf"
    alpha: float = 0.5
    beta: float = 2.0
    kappa: float = 0.0


class SRUKF(Estimator):
    """Batched SR-UKF, thesis eqs 5.12–5.29.

    Args:
        model: the filter model, bound to a batch of B runs.
        alpha, beta, kappa: UT parameters. ``W0(c)`` may be negative (small α); eqs 5.19 and
            5.24 then become Cholesky downdates, and a downdate that would make a covariance
            indefinite flags its run as failed (:class:`~quadest.errors.DowndateError`).
    """

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "sqrt_covariance"})
    config_name = "srukf"
    Params = SRUKFParams

    def __init__(self, model: FilterModel, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0) -> None:
        super().__init__(model)
        self.weights = ut_weights(model.n, alpha, beta, kappa)
        self.sqrt_Q = np.linalg.cholesky(model.Q)  # Sv = √Rv (5.13)
        self.sqrt_R = np.linalg.cholesky(model.R)  # Sn = √Rn (5.14)
        self._sqrt_w1 = np.sqrt(self.weights.wc[1])

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        """x̂0 = E[x0], Sx0 = chol(P0) (eqs 5.12–5.14)."""
        self.x = np.array(x0, dtype=float, copy=True)
        self.S = np.linalg.cholesky(P0)
        self._x_safe, self._S_safe = self.x.copy(), self.S.copy()
        self._reset_failures(self.x.shape[0])
        self._nu = np.zeros((self.x.shape[0], self.model.m))
        self._Sy = np.broadcast_to(self.sqrt_R, (self.x.shape[0], *self.sqrt_R.shape)).copy()

    def _cholupdate(self, S: np.ndarray, u: np.ndarray, nu: float) -> np.ndarray:
        try:
            return cholupdate(S, u, nu)
        except DowndateError as err:
            self.flag(err.runs, err.reason)
            return err.result

    def _factor(self, points: np.ndarray, mean: np.ndarray, sqrt_noise: np.ndarray) -> np.ndarray:
        """qr{[√W1(c)(χ_1:2n − mean), √noise]} then cholupdate with χ_0 − mean by W0(c)
        (eqs 5.18–5.19 and 5.23–5.24)."""
        dev = points[:, 1:, :] - mean[:, None, :]
        B = points.shape[0]
        noise = np.broadcast_to(sqrt_noise, (B, *sqrt_noise.shape))
        A = np.concatenate([self._sqrt_w1 * np.swapaxes(dev, -1, -2), noise], axis=-1)
        return self._cholupdate(qr_factor(A), points[:, 0, :] - mean, self.weights.wc[0])

    def predict(self, u: np.ndarray) -> None:
        w = self.weights
        X = sigma_points(self.x, self.S, w.gamma)  # (5.15)
        X_pred = self.model.f(X, u)  # (5.16)
        x_pred = weighted_mean(X_pred, w)  # (5.17)
        self.S = self._factor(X_pred, x_pred, self.sqrt_Q)  # (5.18)-(5.19)
        self.x = x_pred
        self.quarantine(self.x, self.S, self._x_safe, self._S_safe)

    def update(self, z: np.ndarray, u: np.ndarray) -> None:
        w = self.weights
        X = sigma_points(self.x, self.S, w.gamma)  # (5.20) redraw
        Y = self.model.h(X, u)  # (5.21)
        y_pred = weighted_mean(Y, w)  # (5.22)
        Sy = self._factor(Y, y_pred, self.sqrt_R)  # (5.23)-(5.24)
        dX = X - self.x[:, None, :]
        dY = Y - y_pred[:, None, :]
        Pxy = np.swapaxes(w.wc[:, None] * dX, -1, -2) @ dY  # (5.25)
        K = kalman_gain(Pxy, Sy)  # (5.26)
        self._nu = z - y_pred
        self._Sy = Sy
        self.x = self.x + (K @ self._nu[..., None])[..., 0]  # (5.27)
        U = K @ Sy  # (5.28)
        self.S = self._cholupdate(self.S, U, -1.0)  # (5.29)
        self.quarantine(self.x, self.S, self._x_safe, self._S_safe)

    @property
    def mean(self) -> np.ndarray:
        return self.x

    @property
    def covariance(self) -> np.ndarray:
        return self.S @ np.swapaxes(self.S, -1, -2)

    @property
    def sqrt_covariance(self) -> np.ndarray:
        return self.S

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self._nu, self._Sy
