"""Third-degree cubature Kalman filter (Arasaratnam & Haykin 2009, IEEE TAC 54(6)), batched.

The example of ``docs/plugins.md``: written from the paper by following the plugin contract,
in this module and ``conf/estimator/ckf.yaml`` only. Cubature points ``ξ = √n [I, −I]`` with
equal weights ``1/(2n)``, mapped by ``x̂ + S ξ`` with ``P = S Sᵀ``; covariance form, the points
redrawn before the update. It equals the UKF with α = 1, β = 0, κ = 0 (a free identity test).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadest.estimators.base import Estimator
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky, kalman_gain, unscented_transform


@dataclass
class CKFParams:
    """Configuration of ``estimator=ckf`` (the third-degree rule has no parameters)."""

    kind: str = "ckf"


@dataclass(frozen=True)
class _CubatureRule:
    points: np.ndarray  # (2n, n) unit points ξ
    wm: np.ndarray  # (2n,) mean weights
    wc: np.ndarray  # (2n,) covariance weights


class CKF(Estimator):
    """Batched third-degree CKF: every array carries the leading run axis B."""

    config_name = "ckf"
    Params = CKFParams
    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation"})

    def __init__(self, model: FilterModel) -> None:
        super().__init__(model)
        n = model.n
        w = np.full(2 * n, 1.0 / (2 * n))
        self.rule = _CubatureRule(np.sqrt(n) * np.concatenate([np.eye(n), -np.eye(n)]), w, w)

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self.x = np.array(x0, dtype=float, copy=True)
        self.P = np.array(P0, dtype=float, copy=True)
        self._x_safe, self._P_safe = self.x.copy(), self.P.copy()
        self._reset_failures(self.x.shape[0])
        self._nu = np.zeros((self.x.shape[0], self.model.m))
        self._Sy = np.broadcast_to(np.linalg.cholesky(self.model.R), (self.x.shape[0], self.model.m, self.model.m))

    def _points(self) -> np.ndarray:
        """Cubature points x̂ + S ξ (B, 2n, n); runs whose P is not positive definite are flagged."""
        S, bad = batched_cholesky(self.P)
        if bad.any():
            self.flag(np.flatnonzero(bad), "covariance not positive definite")
            S[bad] = np.linalg.cholesky(self._P_safe[bad])
        return self.x[:, None, :] + self.rule.points @ np.swapaxes(S, -1, -2)

    def predict(self, u: np.ndarray) -> None:
        X = self.model.f(self._points(), u)
        self.x, self.P = unscented_transform(X, self.rule, self.model.Q)
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)

    def update(self, z: np.ndarray, u: np.ndarray) -> None:
        X = self._points()
        Y = self.model.h(X, u)
        y_pred, Pyy = unscented_transform(Y, self.rule, self.model.R)
        Sy, bad = batched_cholesky(Pyy)
        if bad.any():
            self.flag(np.flatnonzero(bad), "innovation covariance not positive definite")
            Sy[bad] = self._Sy[bad]
        dX = X - self.x[:, None, :]
        Pxy = np.swapaxes(self.rule.wc[:, None] * dX, -1, -2) @ (Y - y_pred[:, None, :])
        K = kalman_gain(Pxy, Sy)
        self._nu, self._Sy = z - y_pred, Sy
        self.x = self.x + (K @ self._nu[..., None])[..., 0]
        self.P = self.P - K @ Pyy @ np.swapaxes(K, -1, -2)
        self.P = 0.5 * (self.P + np.swapaxes(self.P, -1, -2))
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)

    @property
    def mean(self) -> np.ndarray:
        return self.x

    @property
    def covariance(self) -> np.ndarray:
        return self.P

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self._nu, self._Sy
