"""The filters' initial condition: the covariance P0 and the per-run estimates x0 ~ N(truth, P0)."""

from __future__ import annotations

import numpy as np


def initial_covariance(std: np.ndarray, correlation: float) -> np.ndarray:
    """``P0 = D C D`` with ``D = diag(std)`` and equicorrelation ``C = (1 − ρ) I + ρ 11ᵀ``."""
    n = std.size
    C = (1.0 - correlation) * np.eye(n) + correlation * np.ones((n, n))
    return std[:, None] * C * std[None, :]


def draw_initial_estimates(truth0: np.ndarray, P0: np.ndarray, rngs: list[np.random.Generator]) -> np.ndarray:
    """(B, n) initial estimates ``truth0[i] + L0 w_i`` with ``L0 L0ᵀ = P0`` and ``w_i ~ N(0, I)``
    drawn from run ``i``'s generator."""
    L0 = np.linalg.cholesky(P0)
    return np.array([truth0[i] + L0 @ rng.standard_normal(P0.shape[0]) for i, rng in enumerate(rngs)])
