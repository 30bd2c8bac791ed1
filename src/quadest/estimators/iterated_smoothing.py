"""Iterated smoothers: the whole trajectory re-linearised about the previous smoothed estimate.

Särkkä & Svensson (2023): the iterated extended RTS smoother (IERTS, Algorithm 13.5, Gauss–Newton
on the MAP trajectory; Bell 1994) and the iterated posterior-linearisation smoother (IPLS,
Algorithm 14.22; García-Fernández, Svensson & Särkkä 2017). Both are one loop over a
:class:`~quadest.estimators.integrations.Linearisation`:

1. about the current nominal trajectory ``N(n_k, Π_k)``, k = 0..K (first: the filter's own
   output, with the prior ``(m_0, P_0)`` at k = 0), make every transition ``k−1 → k`` affine about
   ``N(n_{k−1}, Π_{k−1})`` and every measurement of step k about ``N(n_k, Π_k)`` (Taylor: at the
   mean, the IERTS; statistical linear regression with a rule: the IPLS);
2. run the Kalman filter on the affine model from the prior ``(m_0, P_0)``:
   ``m⁻ = f̄ ⊞ A (m ⊟ n_{k−1})``, ``P⁻ = A P Aᵀ + Λ``, then for each measurement
   ``ν = r(z, ȳ) − H (m⁻ ⊟ n_k)``, the Kalman update;
3. run the RTS smoother on the same affine model back to k = 0 (the initial state is smoothed
   too): ``G = P Aᵀ (P⁻)⁻¹``, ``m^s = m ⊞ G (m^s_{+1} ⊟ m⁻)``, ``P^s = P + G (P^s_{+1} − P⁻) Gᵀ``;
4. the smoothed trajectory is the next nominal one.

On a linear-Gaussian model every linearisation is exact and one iteration is the RTS smoother.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.estimators.gaussian_steps import symmetric
from quadest.estimators.integrations import Linearisation
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky, kalman_gain
from quadest.numerics import matrix_transpose as _t


@dataclass(frozen=True)
class Update:
    """One measurement update of a step: the sensor (``None``: primary), ``z`` and the input."""

    sensor: str | None
    z: np.ndarray
    u: np.ndarray


@dataclass
class Step:
    """The transition into a step (its input ``u``) and the updates made at it, in order."""

    u: np.ndarray
    updates: list[Update] = field(default_factory=list)


def _factor(A: np.ndarray, what: str) -> np.ndarray:
    """Lower factors; a run whose matrix is not positive definite gets the identity (runs the
    filter flagged are left out of the smoothed result by the caller)."""
    L, bad = batched_cholesky(A)
    L[bad] = np.eye(A.shape[-1])
    return L


def iterated_smoother(
    model: FilterModel,
    linearisation: Linearisation,
    x0: np.ndarray,
    P0: np.ndarray,
    steps: list[Step],
    means: np.ndarray,
    covariances: np.ndarray,
    iterations: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed means (K+1, B, n) and covariances (K+1, B, n_err, n_err) of steps 0..K after
    ``iterations`` re-linearisations (module docstring), started from the nominal trajectory
    ``means``/``covariances`` (K+1, B, ·), the prior ``x0``/``P0`` and the recorded ``steps``."""
    K = len(steps)
    if means.shape[0] != K + 1:
        raise ValueError(f"{K} recorded steps need {K + 1} nominal means, got {means.shape[0]}")
    nominal_m, nominal_P = means.copy(), covariances.copy()
    nominal_m[0], nominal_P[0] = x0, P0
    for _ in range(iterations):
        transitions = [
            linearisation.transition(model, nominal_m[k], nominal_P[k], steps[k].u, _factor) for k in range(K)
        ]
        filtered_m, filtered_P = np.empty_like(nominal_m), np.empty_like(nominal_P)
        filtered_m[0], filtered_P[0] = x0, P0
        m, P = x0, P0
        for k, step in enumerate(steps, start=1):
            m, P = _affine_predict(model, transitions[k - 1], nominal_m[k - 1], m, P)
            for update in step.updates:
                affine = linearisation.measurement(model, update.sensor, nominal_m[k], nominal_P[k], update.u, _factor)
                H = affine.jacobian
                nu = model.measurement(update.sensor).innovation(update.z, affine.mean)
                nu = nu - (H @ model.boxminus(m, nominal_m[k])[..., None])[..., 0]
                S = symmetric(H @ P @ _t(H) + affine.noise)
                gain = kalman_gain(P @ _t(H), _factor(S, "innovation covariance"))
                m = model.boxplus(m, (gain @ nu[..., None])[..., 0])
                P = symmetric(P - gain @ S @ _t(gain))
            filtered_m[k], filtered_P[k] = m, P
        smoothed_m, smoothed_P = np.empty_like(nominal_m), np.empty_like(nominal_P)
        smoothed_m[K], smoothed_P[K] = filtered_m[K], filtered_P[K]
        for k in range(K - 1, -1, -1):
            A = transitions[k].jacobian
            m_pred, P_pred = _affine_predict(model, transitions[k], nominal_m[k], filtered_m[k], filtered_P[k])
            G = kalman_gain(filtered_P[k] @ _t(A), _factor(P_pred, "predicted covariance"))
            delta = (G @ model.boxminus(smoothed_m[k + 1], m_pred)[..., None])[..., 0]
            smoothed_m[k] = model.boxplus(filtered_m[k], delta)
            smoothed_P[k] = symmetric(filtered_P[k] + G @ (smoothed_P[k + 1] - P_pred) @ _t(G))
        nominal_m, nominal_P = smoothed_m, smoothed_P
    return nominal_m, nominal_P


def _affine_predict(model: FilterModel, affine, nominal: np.ndarray, m: np.ndarray, P: np.ndarray):
    """``f̄ ⊞ A (m ⊟ n)`` and ``A P Aᵀ + Λ`` of the affine transition made about ``n``."""
    A = affine.jacobian
    mean = model.boxplus(affine.mean, (A @ model.boxminus(m, nominal)[..., None])[..., 0])
    return mean, symmetric(A @ P @ _t(A) + affine.noise)
