"""Gaussian fixed-interval and fixed-lag smoothing, from the filters' own predict steps.

Rauch, Tung & Striebel (1965) for the linearised filters; Särkkä (2008, "Unscented Rauch–Tung–
Striebel smoother", IEEE TAC 53(3)) for a sigma-point rule, whose cross-covariance
``C_k = Cov(x_k, x_{k+1} | y_{1:k})`` comes from the same points the filter propagated; the
backward recursion is then one for every integration (Särkkä 2013, §8–§9):

    G_k = C_k (P⁻_{k+1})⁻¹,
    x̂_{k|K} = x̂_{k|k} ⊞ G_k (x̂_{k+1|K} ⊟ x̂⁻_{k+1}),
    P_{k|K} = P_{k|k} − G_k P⁻_{k+1} G_kᵀ + G_k P_{k+1|K} G_kᵀ.

The filter computes, right after each predict, a :class:`SmootherStep`: the gain ``G_k`` (two
triangular solves against the factor of ``P⁻_{k+1}``), the predicted mean and the *residual*
``Z_k`` with ``Z_k Z_kᵀ = P_{k|k} − G_k P⁻_{k+1} G_kᵀ`` (square-root form) or ``Z_k`` equal to
it (covariance form). The residual is built from deviations, never by subtracting covariances:
with the points' state deviations ``DX`` and predicted deviations ``D⁻`` (or, linearised,
``DX = S`` and ``D⁻ = F S``), ``E = DX − G D⁻`` has ``Σ wc E Eᵀ + G Q Gᵀ = P_{k|k} − G P⁻ Gᵀ``
because ``C = Σ wc DX D⁻ᵀ = G P⁻``; for the linearisation that is the Joseph form
``(I − G F) P (I − G F)ᵀ + G Q Gᵀ``. The backward recursion is then

    covariance form:  P_{k|K} = Z_k + G_k P_{k+1|K} G_kᵀ,
    square-root form: S_{k|K} = qr([Z_k, G_k S_{k+1|K}]),

so the square-root smoother never forms a covariance (the square-root URTS of Särkkä 2013,
§9.3, in its array form). On a manifold state (the MEKF) the smoothed correction
``δ = G_k (x̂_{k+1|K} ⊟ x̂⁻_{k+1})`` is injected with ``⊞`` and, when the filter applies the reset
Jacobian, the smoothed covariance is reset like the filter's (``P ← J P Jᵀ``, ``J`` the model's
``reset_jacobian`` at the injected correction).

Fixed lag ``L``: the estimate of ``x_k`` given ``y_{1:min(k+L, K)}``, the same recursion run back
over the window that ends ``L`` steps later (cost ``O(L)`` per step).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from quadest.estimators.gaussian_steps import joseph_covariance, symmetric
from quadest.numerics import kalman_gain, qr_factor
from quadest.numerics import matrix_transpose as _t
from quadest.numerics.rules import IntegrationRule

Manifold = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class SmootherStep:
    """What the backward pass needs from the transition ``k → k+1``: the smoother gain ``G_k``
    (B, n, n), the predicted mean ``x̂⁻_{k+1}`` (B, n_state) and the residual ``Z_k`` (B, n, n):
    ``P_{k|k} − G_k P⁻_{k+1} G_kᵀ`` (covariance form) or a factor of it (square-root form)."""

    gain: np.ndarray
    predicted_mean: np.ndarray
    residual: np.ndarray


@dataclass(frozen=True)
class SmoothingForm:
    """How a smoother keeps the second moment: ``square_root`` (lower factors) or covariances;
    and the model's manifold operations (``None``: vector states) and reset Jacobian."""

    square_root: bool = False
    boxplus: Manifold | None = None
    boxminus: Manifold | None = None
    reset_jacobian: Manifold | None = None

    def combine(self, step: SmootherStep, spread_next: np.ndarray) -> np.ndarray:
        """``Z + G P Gᵀ`` or ``qr([Z, G S])``."""
        G = step.gain
        if self.square_root:
            return qr_factor(np.concatenate([step.residual, G @ spread_next], axis=-1))
        return symmetric(step.residual + G @ spread_next @ _t(G))

    def correct(self, filtered: np.ndarray, step: SmootherStep, smoothed_next: np.ndarray, spread: np.ndarray):
        """Smoothed mean ``x̂_{k|k} ⊞ G (x̂_{k+1|K} ⊟ x̂⁻_{k+1})`` and the spread, reset if asked."""
        if self.boxminus is None:
            innovation = smoothed_next - step.predicted_mean
        else:
            innovation = self.boxminus(smoothed_next, step.predicted_mean)
        delta = (step.gain @ innovation[..., None])[..., 0]
        if self.boxplus is None:
            return filtered + delta, spread
        mean = self.boxplus(filtered, delta)
        if self.reset_jacobian is not None:
            J = self.reset_jacobian(filtered, delta)
            spread = qr_factor(J @ spread) if self.square_root else J @ spread @ _t(J)
        return mean, spread


def rts_backward(
    filtered_means: Sequence[np.ndarray],
    final_spread: np.ndarray,
    steps: Sequence[SmootherStep],
    form: SmoothingForm,
) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-interval smoothing: means (K, B, n_state) and spreads (K, B, n, n) of
    ``x_k | y_{1:K}`` from the filtered means ``x̂_{k|k}`` (K of them), the last filtered spread and
    the ``K − 1`` steps of the transitions (module docstring)."""
    K = len(filtered_means)
    if len(steps) != K - 1:
        raise ValueError(f"{K} filtered means need {K - 1} smoother steps, got {len(steps)}")
    means = np.empty((K, *np.shape(filtered_means[-1])))
    spreads = np.empty((K, *np.shape(final_spread)))
    means[-1], spreads[-1] = filtered_means[-1], final_spread
    for k in range(K - 2, -1, -1):
        spread = form.combine(steps[k], spreads[k + 1])
        means[k], spreads[k] = form.correct(filtered_means[k], steps[k], means[k + 1], spread)
    return means, spreads


def fixed_lag(
    filtered_means: Sequence[np.ndarray],
    filtered_spreads: Sequence[np.ndarray],
    steps: Sequence[SmootherStep],
    form: SmoothingForm,
    lag: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-lag smoothing: ``x_k | y_{1:min(k+lag, K)}`` for every k, means (K, B, n_state) and
    spreads (K, B, n, n); ``lag = 0`` gives the filter, ``lag ≥ K − 1`` the fixed interval."""
    if isinstance(lag, bool) or not isinstance(lag, int | np.integer) or lag < 0:
        raise ValueError(f"lag must be an integer >= 0, got {lag!r}")
    K = len(filtered_means)
    means = np.empty((K, *np.shape(filtered_means[-1])))
    spreads = np.empty((K, *np.shape(filtered_spreads[-1])))
    for k in range(K):
        end = min(k + lag, K - 1)
        mean, spread = filtered_means[end], filtered_spreads[end]
        for j in range(end - 1, k - 1, -1):
            mean, spread = form.correct(filtered_means[j], steps[j], mean, form.combine(steps[j], spread))
        means[k], spreads[k] = mean, spread
    return means, spreads


def linearized_smoother_step(
    P: np.ndarray, F: np.ndarray, Q: np.ndarray, predicted_factor: np.ndarray, predicted_mean: np.ndarray
) -> SmootherStep:
    """The step of the linearised (RTS) smoother: ``G = P Fᵀ (P⁻)⁻¹`` by two triangular solves
    against the factor of ``P⁻``, and the residual in Joseph form ``(I − G F) P (I − G F)ᵀ + G Q Gᵀ``
    (covariance form)."""
    G = kalman_gain(P @ _t(F), predicted_factor)
    return SmootherStep(G, predicted_mean, joseph_covariance(P, F, Q, G))


def sigma_point_smoother_gain(
    rule: IntegrationRule, DX: np.ndarray, D_pred: np.ndarray, dim: int, predicted_factor: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The unscented smoother's gain ``G = C (P⁻)⁻¹`` with ``C = Σ wc DX D⁻ᵀ`` (Särkkä 2008, eq. 19)
    from the state deviations ``DX`` (B, L, n) of the points before ``f`` and their deviations
    ``D_pred`` after it; and ``E = DX − G D⁻`` (B, L, n), whose rule spread plus ``G Q Gᵀ`` is the
    residual ``P − G P⁻ Gᵀ``."""
    G = kalman_gain(rule.cross_covariance(DX, D_pred, dim), predicted_factor)
    return G, DX - D_pred @ _t(G)
