"""Iterated extended Kalman filter (Bell & Cathey 1993, IEEE TAC 38(2)) for quadest.

The time update is the EKF's; the measurement update relinearises ``h`` at the current iterate:
``x_{i+1} = x̄ + K_i (z − h(x_i) − H_i (x̄ − x_i))`` with ``H_i`` the Jacobian at ``x_i`` and
``K_i = P̄ H_iᵀ (H_i P̄ H_iᵀ + R)⁻¹``. One iteration is the EKF; on a linear model every
iteration count gives the Kalman filter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadest.estimators import SingleRunEstimator


@dataclass
class IEKFParams:
    kind: str = "single_run_iekf"
    iterations: int = 3


class IteratedEKF(SingleRunEstimator):
    """One run at a time; quadest's adapter loops it over the Monte Carlo batch."""

    Params = IEKFParams
    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation"})

    def __init__(self, model, iterations: int = 3) -> None:
        super().__init__(model)
        if not (isinstance(iterations, int) and iterations >= 1):
            raise ValueError(f"single_run_iekf: iterations must be an integer >= 1, got {iterations!r}")
        self.iterations = iterations

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self.x, self.P = np.array(x0, dtype=float), np.array(P0, dtype=float)

    def predict(self, u: np.ndarray) -> None:
        F = self.model.F(self.x[None], u[None])[0]
        self.x = self.model.f(self.x[None, None], u[None])[0, 0]
        self.P = F @ self.P @ F.T + self.model.Q

    def update(self, z: np.ndarray, u: np.ndarray) -> None:
        prior, P = self.x, self.P
        x = prior
        for _ in range(self.iterations):
            H = self.model.H(x[None], u[None])[0]
            S = H @ P @ H.T + self.model.R
            K = np.linalg.solve(S, H @ P).T
            residual = z - self.model.h(x[None, None], u[None])[0, 0]
            x = prior + K @ (residual - H @ (prior - x))
        self.nu, self.S = residual, S
        I_KH = np.eye(x.size) - K @ H
        self.x, self.P = x, I_KH @ P @ I_KH.T + K @ self.model.R @ K.T

    @property
    def mean(self) -> np.ndarray:
        return self.x

    @property
    def covariance(self) -> np.ndarray:
        return self.P

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self.nu, np.linalg.cholesky(self.S)
