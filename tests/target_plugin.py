"""Estimators for the plugin tests, importable by ``_target_``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.estimators.base import SingleRunEstimator


@dataclass
class LinearizedKFParams:
    kind: str = "linearized_kf"
    inflation: float = 1.0


class LinearizedKF(SingleRunEstimator):
    """A single-run EKF written in numpy from the model interface only: a minimal plugin."""

    Params = LinearizedKFParams

    def __init__(self, model, inflation: float = 1.0) -> None:
        super().__init__(model)
        if not inflation >= 1.0:
            raise ValueError(f"inflation must be >= 1, got {inflation}")
        self.inflation = inflation

    def initialize(self, x0, P0):
        self.x, self.P = np.array(x0, dtype=float), np.array(P0, dtype=float)

    def predict(self, u):
        F = self.model.F(self.x[None], u[None])[0]
        self.x = self.model.f(self.x[None, None], u[None])[0, 0]
        self.P = self.inflation * F @ self.P @ F.T + self.model.Q

    def update(self, z, u):
        H = self.model.H(self.x[None], u[None])[0]
        S = H @ self.P @ H.T + self.model.R
        K = np.linalg.solve(S, H @ self.P).T
        self.x = self.x + K @ (z - self.model.h(self.x[None, None], u[None])[0, 0])
        I_KH = np.eye(self.x.size) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ self.model.R @ K.T

    @property
    def mean(self):
        return self.x

    @property
    def covariance(self):
        return self.P


class Crashes(LinearizedKF):
    """Raises at the fifth update of the second instance created (run 1 of a batch built in
    order); reset ``Crashes.created`` before a test."""

    created = 0

    def __init__(self, model, inflation: float = 1.0) -> None:
        super().__init__(model, inflation)
        self.index, self.updates = Crashes.created, 0
        Crashes.created += 1

    def update(self, z, u):
        self.updates += 1
        if self.index == 1 and self.updates == 5:
            raise RuntimeError("plugin exploded")
        super().update(z, u)


class NotAnEstimator:
    """Meets no contract."""
