"""Weights of the scaled symmetric unscented transform.

Thesis (seed 000) eqs 5.1–5.6; the same scaling as van der Merwe's scaled UT, which filterpy's
``MerweScaledSigmaPoints`` implements, so the two can be compared term by term. The points, the
mean and the square-root columns are the unscented rule's (:mod:`quadest.numerics.rules`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
