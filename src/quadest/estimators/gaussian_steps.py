"""Gaussian predict and update steps, written once: pure batched functions that every Gaussian
filter of quadest and both Gaussian particle proposals are built from (not the filterpy baselines
``ekf`` and ``ukf``, which run filterpy's own steps: they are the independent reference).

The structure is dynamax's generalized Gaussian state-space inference (``generalized_gaussian_ssm``,
after Tronarp, García-Fernández & Särkkä 2018 and Särkkä 2013, §5–§6): a filter step needs the
moments of a nonlinear map of a Gaussian, and how they are approximated is the filter's
*integration*:

- **linearisation** (the EKF, its error-state form and the EKPF's proposal): first-order Taylor
  moments, :func:`linearized_covariance` and :func:`linearized_moments`;
- **a sigma-point rule** (:mod:`quadest.numerics.rules`: unscented, central differences,
  cubature, Gauss–Hermite; the sigma-point family and the UPF's proposal): points
  :func:`sigma_points`, their weighted mean :func:`point_mean`, :func:`sigma_point_covariance`
  and :func:`sigma_point_moments`.

Whatever gave the moments, conditioning on a measurement is one function:
:func:`kalman_correction` (gain by two triangular solves, correction ``K ν``, or the Huber
M-estimate in its place), then the posterior second moment by :func:`covariance_posterior`
(``P − K Pyy Kᵀ``) or :func:`joseph_covariance` (valid for any gain). Square-root filters keep the
same moments as factors (:class:`~quadest.estimators.sigma_point.SquareRootSigmaPointFilter`).

Every array has leading batch axes: ``(B,)`` for the runs of a filter, ``(B, N)`` for the particles
of the EKPF and UPF. A step never flags a run: what can fail (a factorisation) is left to the
estimator, which knows what to flag and what to substitute. Smoothers and iterated filters reuse
the same steps: the cross-covariance of consecutive states is ``P Fᵀ`` for the linearisation and
``rule.cross_covariance`` of the point deviations before and after ``f`` for a rule.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from quadest.numerics import kalman_gain
from quadest.numerics import matrix_transpose as _t
from quadest.numerics.huber import HuberSettings, HuberStep, huber_update
from quadest.numerics.joseph import joseph_covariance
from quadest.numerics.rules import IntegrationRule, rule_mean

__all__ = [
    "KalmanCorrection",
    "MeasurementMoments",
    "covariance_posterior",
    "joseph_covariance",
    "kalman_correction",
    "linearized_covariance",
    "linearized_moments",
    "point_mean",
    "sigma_point_covariance",
    "sigma_point_moments",
    "sigma_points",
    "symmetric",
]

Manifold = Callable[[np.ndarray, np.ndarray], np.ndarray]


def symmetric(P: np.ndarray) -> np.ndarray:
    """``(P + Pᵀ)/2``: a covariance computed in floating point, made exactly symmetric."""
    return 0.5 * (P + _t(P))


@dataclass(frozen=True)
class MeasurementMoments:
    """Moments of the predicted measurement ``y = h(x) + v`` for ``x ~ N(x̂⁻, P⁻)``: the mean
    ``ŷ`` (..., m), the innovation covariance ``Pyy`` (..., m, m, the noise included) and the
    cross-covariance ``Pxy`` (..., n, m)."""

    mean: np.ndarray
    cov: np.ndarray
    cross: np.ndarray


# --- linearisation: the EKF's integration ---


def linearized_covariance(F: np.ndarray, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Predicted covariance ``P⁻ = F P Fᵀ + Q`` of the linearised time update, ``F`` the Jacobian of
    ``f`` at the posterior mean (the mean itself is ``f(x̂)``; Solà 2017 eqs 268–270).

    The cross-covariance of ``x_k`` and ``x_{k+1}`` a smoother needs is ``P Fᵀ``."""
    return F @ P @ _t(F) + Q


def linearized_moments(y: np.ndarray, H: np.ndarray, P: np.ndarray, R: np.ndarray) -> MeasurementMoments:
    """First-order moments of a measurement: ``ŷ = h(x̂⁻)`` (given as ``y``), ``Pxy = P Hᵀ`` and
    ``Pyy = H Pxy + R`` for the Jacobian ``H`` (..., m, n) at the prior mean."""
    cross = P @ _t(H)
    return MeasurementMoments(y, H @ cross + R, cross)


# --- sigma points: a rule's integration ---


def sigma_points(rule: IntegrationRule, x: np.ndarray, S: np.ndarray, boxplus: Manifold | None = None) -> np.ndarray:
    """Points (..., L, d) of the rule about ``x`` (..., n) with lower factor ``S`` (..., d, d),
    ``d ≥ n``: ``x ⊞ offset`` in the state's coordinates (``x + offset`` without ``boxplus``),
    and the remaining ``d − n`` coordinates (augmented noise) as offsets from zero (seed 000,
    eqs 5.15 and 5.20; augmented: van der Merwe 2004)."""
    offsets = rule.offsets(S)
    n = x.shape[-1]
    if boxplus is None:
        X = offsets.copy()
        X[..., :n] += x[..., None, :]
        return X
    X = boxplus(x[..., None, :], offsets[..., :n])
    return np.concatenate([X, offsets[..., n:]], axis=-1)


def point_mean(
    Y: np.ndarray, wm: np.ndarray, boxplus: Manifold | None = None, boxminus: Manifold | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (..., m) of points ``Y`` (..., L, m) and their deviations from it (..., L, m)
    (seed 000, eqs 5.8, 5.17, 5.22). On a manifold (``boxplus``/``boxminus`` given) the mean is
    ``Y0 ⊞ Σ wm_i (Y_i ⊟ Y0)`` and the deviations are ``Y_i ⊟ mean``."""
    if boxplus is None or boxminus is None:
        mean = rule_mean(Y, wm)
        return mean, Y - mean[..., None, :]
    Y0 = Y[..., :1, :]
    mean = boxplus(Y0, (wm[1:] @ boxminus(Y[..., 1:, :], Y0))[..., None, :])[..., 0, :]
    return mean, boxminus(Y, mean[..., None, :])


def sigma_point_covariance(
    rule: IntegrationRule, D: np.ndarray, dim: int, noise_cov: np.ndarray | float | None = None
) -> np.ndarray:
    """``Σ wc_i D_i D_iᵀ`` of deviations ``D`` (..., L, m) of points of dimension ``dim``, plus the
    additive noise covariance, symmetrised (seed 000, eqs 5.9, 5.18–5.19 in covariance form)."""
    P = rule.covariance(D, dim)
    if noise_cov is not None:
        P = P + noise_cov
    return symmetric(P)


def sigma_point_moments(
    rule: IntegrationRule,
    DX: np.ndarray,
    DY: np.ndarray,
    dim: int,
    y_mean: np.ndarray,
    noise_cov: np.ndarray | None = None,
) -> MeasurementMoments:
    """Moments of a measurement from state deviations ``DX`` (..., L, n) and measurement
    deviations ``DY`` (..., L, m) of the same points (dimension ``dim``): ``Pyy`` by
    :func:`sigma_point_covariance` (eqs 5.23–5.24 in covariance form) and ``Pxy`` (eq. 5.25)."""
    return MeasurementMoments(
        y_mean, sigma_point_covariance(rule, DY, dim, noise_cov), rule.cross_covariance(DX, DY, dim)
    )


# --- conditioning on a measurement: one function whatever gave the moments ---


@dataclass(frozen=True)
class KalmanCorrection:
    """The conditioning of a prior on one measurement: the gain ``K`` (..., n, m), the correction
    ``δx̂`` (..., n) that moves the prior mean (``x̂ = x̂⁻ ⊞ δx̂``) and, with Huber settings, the
    Huber step (whose robust runs replace ``K ν`` and the posterior covariance)."""

    gain: np.ndarray
    correction: np.ndarray
    huber: HuberStep | None = None


def kalman_correction(
    innovation: np.ndarray,
    cross: np.ndarray,
    innovation_factor: np.ndarray,
    huber: HuberSettings | None = None,
    prior_factor: np.ndarray | None = None,
) -> KalmanCorrection:
    """Gain ``K = Pxy (Sy Syᵀ)⁻¹`` by two triangular solves (seed 000, eq. 5.26) and correction
    ``K ν`` (eq. 5.27); with ``huber`` settings, the runs whose whitened residual exceeds the
    threshold take the Huber M-estimate instead (Karlgaard & Schaub 2007,
    :func:`~quadest.numerics.huber.huber_update`; needs the prior's lower factor)."""
    K = kalman_gain(cross, innovation_factor)
    correction = (K @ innovation[..., None])[..., 0]
    if huber is None:
        return KalmanCorrection(K, correction)
    if prior_factor is None:
        raise ValueError("the Huber update needs the prior's lower factor (prior_factor)")
    step = huber_update(innovation, cross, innovation_factor, prior_factor, correction, huber)
    return KalmanCorrection(K, step.correction, step)


def covariance_posterior(P: np.ndarray, K: np.ndarray, Pyy: np.ndarray) -> np.ndarray:
    """``P = P⁻ − K Pyy Kᵀ``, symmetrised: the posterior of the optimal gain (seed 000, eq. 5.11;
    for another gain use :func:`joseph_covariance`)."""
    return symmetric(P - K @ Pyy @ _t(K))
