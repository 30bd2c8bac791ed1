"""The SR-UKF's steps for vector states (seed 000, chapter 5), three batched functions per
filter step instead of some forty numpy calls, used by :class:`~quadest.estimators.srukf.SRUKF`:

- :func:`unscented_points`: the sigma points ``[x̂, x̂ + γ S_i, x̂ − γ S_i]`` (eqs 5.7, 5.15, 5.20);
- :func:`unscented_moments`: mean and square-root covariance of transformed points plus additive
  noise, ``qr{[√W1(c) (Y_1:2n − ȳ), √R]}`` and the ``cholupdate`` by the centre point with
  ``W0(c)`` (eqs 5.17–5.19 for the state, 5.22–5.24 for the measurement);
- :func:`unscented_correction`: ``Pxy``, the gain, the corrected mean and the posterior downdate by
  ``U = K Sy`` (eqs 5.25–5.29).

Each has a readable numpy reference (``*_numpy``) that spells the equations with the batched
helpers of :mod:`quadest.numerics.square_root` and :mod:`quadest.numerics.rules`; the public
functions call the compiled kernels of :mod:`quadest.numerics.compiled` on the ``numba`` backend
(``QUADEST_KERNELS``, docs/benchmarks.md), which do the same arithmetic one run at a time in one
loop and agree with the references to round-off (tests/test_kernels.py). A run whose rank-one
change fails (a downdate that would make the covariance indefinite, or a NaN) is marked in the
returned ``failed`` (B,) and keeps the factor from before that change, as
:class:`~quadest.errors.DowndateError` gives it.
"""

from __future__ import annotations

import numpy as np

from quadest.errors import DowndateError
from quadest.numerics.rules import rule_mean
from quadest.numerics.sigma_points import UTWeights
from quadest.numerics.square_root import _kernels, cholupdate_numpy, kalman_gain_numpy, qr_factor_numpy


def _c(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float)


def unscented_points(x: np.ndarray, S: np.ndarray, gamma: float) -> np.ndarray:
    """Sigma points (B, 2n+1, n) of means ``x`` (B, n) and lower factors ``S`` (B, n, n); see
    :func:`unscented_points_numpy`."""
    kernels = _kernels()
    if kernels is None:
        return unscented_points_numpy(x, S, gamma)
    out = np.empty((x.shape[0], 2 * x.shape[1] + 1, x.shape[1]))
    kernels.unscented_points_kernel(_c(x), _c(S), float(gamma), out)
    return out


def unscented_points_numpy(x: np.ndarray, S: np.ndarray, gamma: float) -> np.ndarray:
    """``X_0 = x̂``, ``X_i = x̂ + γ S_i``, ``X_{n+i} = x̂ − γ S_i`` with ``S_i`` column ``i`` of the
    factor (eqs 5.7, 5.15, 5.20; numpy reference)."""
    cols = gamma * np.swapaxes(S, -1, -2)
    return x[:, None, :] + np.concatenate([np.zeros_like(cols[:, :1]), cols, -cols], axis=1)


def unscented_moments(
    Y: np.ndarray, weights: UTWeights, sqrt_noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(mean (B, m), factor (B, m, m), failed (B,))`` of points ``Y`` (B, 2n+1, m) with the UT
    weights of dimension n and the additive noise factor ``sqrt_noise`` (m, q); see
    :func:`unscented_moments_numpy`."""
    kernels = _kernels()
    if kernels is None:
        return unscented_moments_numpy(Y, weights, sqrt_noise)
    B, _, m = Y.shape
    mean, S, failed = np.empty((B, m)), np.empty((B, m, m)), np.zeros(B, dtype=bool)
    wc0 = weights.wc[0]
    kernels.unscented_moments_kernel(
        _c(Y),
        weights.wm,
        float(np.sqrt(weights.wc[1])),
        float(np.sqrt(abs(wc0))),
        bool(wc0 < 0),
        _c(sqrt_noise),
        mean,
        S,
        failed,
    )
    return mean, S, failed


def unscented_moments_numpy(
    Y: np.ndarray, weights: UTWeights, sqrt_noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and square-root covariance of transformed sigma points plus additive noise (numpy
    reference): ``ȳ = Σ W_i(m) Y_i`` in the deviation form of :func:`~quadest.numerics.rules.rule_mean`
    (eqs 5.17, 5.22); ``S = qr{[√W1(c) (Y_1:2n − ȳ), √R]}`` (eqs 5.18, 5.23); then
    ``S = cholupdate{S, Y_0 − ȳ, W0(c)}``, a downdate when ``W0(c) < 0`` (eqs 5.19, 5.24)."""
    wm, wc = weights.wm, weights.wc
    mean = rule_mean(Y, wm)
    D = Y - mean[:, None, :]
    noise = np.broadcast_to(sqrt_noise, (Y.shape[0], *sqrt_noise.shape))
    S = qr_factor_numpy(np.concatenate([np.sqrt(wc[1]) * np.swapaxes(D[:, 1:], -1, -2), noise], axis=-1))
    failed = np.zeros(Y.shape[0], dtype=bool)
    try:
        S = cholupdate_numpy(S, np.sqrt(abs(wc[0])) * D[:, 0, :, None], 1.0 if wc[0] >= 0 else -1.0)
    except DowndateError as err:
        S, failed[err.runs] = err.result, True
    return mean, S, failed


def unscented_correction(
    X: np.ndarray,
    x: np.ndarray,
    Y: np.ndarray,
    y_mean: np.ndarray,
    wc: np.ndarray,
    Sy: np.ndarray,
    S: np.ndarray,
    z: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(x_post (B, n), S_post (B, n, n), ν (B, m), failed (B,))`` of the measurement correction;
    see :func:`unscented_correction_numpy` for the arguments."""
    kernels = _kernels()
    if kernels is None:
        return unscented_correction_numpy(X, x, Y, y_mean, wc, Sy, S, z)
    B, n = x.shape
    m = y_mean.shape[1]
    x_post, S_post, nu, failed = np.empty((B, n)), np.empty((B, n, n)), np.empty((B, m)), np.zeros(B, dtype=bool)
    kernels.unscented_correction_kernel(
        _c(X), _c(x), _c(Y), _c(y_mean), _c(wc), _c(Sy), _c(S), _c(z), x_post, S_post, nu, failed
    )
    return x_post, S_post, nu, failed


def unscented_correction_numpy(
    X: np.ndarray,
    x: np.ndarray,
    Y: np.ndarray,
    y_mean: np.ndarray,
    wc: np.ndarray,
    Sy: np.ndarray,
    S: np.ndarray,
    z: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The measurement correction (numpy reference), from the points ``X`` (B, L, n) drawn about
    the predicted mean ``x`` (B, n) with factor ``S`` (B, n, n), their images ``Y`` (B, L, m), the
    predicted measurement ``y_mean`` (B, m) with its factor ``Sy`` (B, m, m), the covariance weights
    ``wc`` (L,) and the measurement ``z`` (B, m):

    ``Pxy = Σ W_i(c) (X_i − x̂⁻)(Y_i − ȳ)ᵀ`` (5.25); ``K = (Pxy / Syᵀ) / Sy`` (5.26);
    ``x̂ = x̂⁻ + K (z − ȳ)`` (5.27); ``U = K Sy`` (5.28); ``S = cholupdate{S⁻, U, −1}`` (5.29).
    """
    DX, DY = X - x[:, None, :], Y - y_mean[:, None, :]
    Pxy = np.swapaxes(wc[:, None] * DX, -1, -2) @ DY
    K = kalman_gain_numpy(Pxy, Sy)
    nu = z - y_mean
    x_post = x + (K @ nu[..., None])[..., 0]
    failed = np.zeros(x.shape[0], dtype=bool)
    try:
        S_post = cholupdate_numpy(S, K @ Sy, -1.0)
    except DowndateError as err:
        S_post, failed[err.runs] = err.result, True
    return x_post, S_post, nu, failed
