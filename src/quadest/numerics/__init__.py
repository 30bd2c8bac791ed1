"""Shared numerics for every sigma-point filter: the integration rules (points, mean weights,
square-root columns: :mod:`quadest.numerics.rules`), the UT weights, the square-root helpers (qr,
cholupdate, a semi-definite square root), the triangular-solve Kalman gain and the batched matrix
transpose; and the particle filters' resampling schemes (:mod:`quadest.numerics.resampling`).

Everything works on a leading batch axis of independent Monte Carlo runs.
"""

from quadest.numerics.resampling import RESAMPLING_SCHEMES, effective_sample_size, resample, resample_from_uniforms
from quadest.numerics.sigma_points import UTWeights, ut_weights
from quadest.numerics.square_root import batched_cholesky, cholupdate, kalman_gain, psd_sqrt, qr_factor, whiten
from quadest.numerics.transpose import matrix_transpose

__all__ = [
    "RESAMPLING_SCHEMES",
    "UTWeights",
    "batched_cholesky",
    "cholupdate",
    "effective_sample_size",
    "kalman_gain",
    "matrix_transpose",
    "psd_sqrt",
    "qr_factor",
    "resample",
    "resample_from_uniforms",
    "ut_weights",
    "whiten",
]
