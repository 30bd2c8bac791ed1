"""Shared numerics for every sigma-point filter: weights, sigma points, the unscented
transform, the square-root helpers (qr, cholupdate) and the triangular-solve Kalman gain; and
the particle filters' resampling schemes (:mod:`quadest.numerics.resampling`).

Everything works on a leading batch axis of independent Monte Carlo runs.
"""

from quadest.numerics.resampling import RESAMPLING_SCHEMES, effective_sample_size, resample, resample_from_uniforms
from quadest.numerics.sigma_points import (
    UTWeights,
    sigma_points,
    unscented_transform,
    ut_weights,
    weighted_mean,
)
from quadest.numerics.square_root import batched_cholesky, cholupdate, kalman_gain, psd_sqrt, qr_factor, whiten

__all__ = [
    "RESAMPLING_SCHEMES",
    "UTWeights",
    "batched_cholesky",
    "cholupdate",
    "effective_sample_size",
    "kalman_gain",
    "psd_sqrt",
    "qr_factor",
    "resample",
    "resample_from_uniforms",
    "sigma_points",
    "unscented_transform",
    "ut_weights",
    "weighted_mean",
    "whiten",
]
