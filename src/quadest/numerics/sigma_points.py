"""Scaled symmetric sigma points, their weights and the unscented transform.

Thesis (seed 000) eqs 5.1–5.9; the same scaling as van der Merwe's scaled UT, which filterpy's
``MerweScaledSigmaPoints`` implements, so the two can be compared term by term.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class Weights(Protocol):
    """Any set of mean and covariance weights (a UT, a cubature rule, ...)."""

    wm: np.ndarray
    wc: np.ndarray


@dataclass(frozen=True)
class UTWeights:
    """Scaling and weights of the scaled symmetric unscented transform (eqs 5.2–5.6).

    Attributes:
        n: state dimension.
        lam: λ = α²(n + κ) − n.
        gamma: γ = √(n + λ), the spread of the points around the mean.
        wm: mean weights W(m), shape (2n+1,).
        wc: covariance weights W(c), shape (2n+1,). ``wc[0]`` is negative for small α
            (about −1e6 at α = 1e-3, n = 6); the square-root filter handles it with a downdate.
    """

    n: int
    alpha: float
    beta: float
    kappa: float
    lam: float
    gamma: float
    wm: np.ndarray
    wc: np.ndarray


def ut_weights(n: int, alpha: float, beta: float, kappa: float) -> UTWeights:
    """Weights of the scaled symmetric UT (eqs 5.2–5.6).

    Raises:
        ValueError: if α ≤ 0 or n + λ ≤ 0 (the points would not be real).
    """
    if not alpha > 0.0:
        raise ValueError(f"alpha must be > 0, got {alpha}")
    lam = alpha**2 * (n + kappa) - n
    if not n + lam > 0.0:
        raise ValueError(f"n + lambda = alpha^2 (n + kappa) must be > 0, got {n + lam} (n={n})")
    c = 0.5 / (n + lam)
    wm = np.full(2 * n + 1, c)
    wc = np.full(2 * n + 1, c)
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + (1.0 - alpha**2 + beta)
    return UTWeights(n, alpha, beta, kappa, lam, float(np.sqrt(n + lam)), wm, wc)


def sigma_points(x: np.ndarray, S: np.ndarray, gamma: float) -> np.ndarray:
    """Symmetric sigma points ``[x, x + γ S, x − γ S]`` (eqs 5.7, 5.15, 5.20).

    ``x`` is (B, n) and ``S`` (B, n, n) a square root with ``P = S Sᵀ``; point ``i`` (1 ≤ i ≤ n)
    uses column ``i`` of ``S``. Returns (B, 2n+1, n).
    """
    cols = gamma * np.swapaxes(S, -1, -2)
    xc = x[..., None, :]
    return np.concatenate([xc, xc + cols, xc - cols], axis=-2)


def weighted_mean(Y: np.ndarray, weights: Weights) -> np.ndarray:
    """``Σ Wi(m) Yi`` (eqs 5.8, 5.17, 5.22) for ``Y`` (B, 2n+1, m), computed as
    ``Y0 + Σ_{i≥1} Wi(m) (Yi − Y0)``.

    The two are equal because the weights sum to one, but the direct sum cancels terms of size
    ``|W0(m)| |Y|`` (about 1e6 |Y| at α = 1e-3), losing about six digits; the deviation form
    keeps them.
    """
    Y0 = Y[..., 0, :]
    return Y0 + weights.wm[1:] @ (Y[..., 1:, :] - Y0[..., None, :])


def unscented_transform(
    Y: np.ndarray, weights: Weights, noise_cov: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of transformed sigma points (eqs 5.8–5.9), covariance form.

    ``Y`` is (B, L, m) with one row per weight (2n+1 for the UT; any rule with ``wm``, ``wc``).
    Returns the mean (B, m) and covariance (B, m, m), plus ``noise_cov``
    when given. The square-root filter does not use this; it is the reference the square-root
    form must equal, and the building block of covariance-form sigma-point filters.
    """
    mean = weighted_mean(Y, weights)
    d = Y - mean[..., None, :]
    cov = np.swapaxes(weights.wc[:, None] * d, -1, -2) @ d
    if noise_cov is not None:
        cov = cov + noise_cov
    return mean, cov
