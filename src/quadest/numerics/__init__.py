"""Shared numerics for every sigma-point filter: weights, sigma points, the unscented
transform, the square-root helpers (qr, cholupdate) and the triangular-solve Kalman gain.

Everything works on a leading batch axis of independent Monte Carlo runs.
"""

from quadest.numerics.sigma_points import (
    UTWeights,
    sigma_points,
    unscented_transform,
    ut_weights,
    weighted_mean,
)
from quadest.numerics.square_root import batched_cholesky, cholupdate, kalman_gain, psd_sqrt, qr_factor, whiten

__all__ = [
    "UTWeights",
    "batched_cholesky",
    "cholupdate",
    "kalman_gain",
    "psd_sqrt",
    "qr_factor",
    "sigma_points",
    "unscented_transform",
    "ut_weights",
    "weighted_mean",
    "whiten",
]
