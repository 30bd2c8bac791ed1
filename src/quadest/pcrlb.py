"""Posterior Cramér–Rao lower bound (Tichavský, Muravchik & Nehorai 1998, IEEE TSP 46(5)).

For additive Gaussian noise, ``x_k = f(x_{k−1}) + v``, ``z_k = h(x_k) + n``, the Fisher
information of the state obeys

    J_k = D22 − D21 (J_{k−1} + D11)⁻¹ D12,      J_0 = P0⁻¹
    D11 = E[Fᵀ Q⁻¹ F],  D12 = D21ᵀ = −E[Fᵀ] Q⁻¹,  D22 = Q⁻¹ + E[Hᵀ R⁻¹ H]

with ``F`` the Jacobian of ``f`` at the true ``x_{k−1}`` and ``H`` that of ``h`` at the true
``x_k``. Expectations are Monte Carlo averages over the runs' true trajectories. Then
``E[(x̂_k − x_k)(x̂_k − x_k)ᵀ] ⪰ J_k⁻¹`` for any estimator, so ``√diag(J_k⁻¹)`` is a floor on the
RMSE at each step. It is a floor, not a target.

The bound assumes the truth follows the filter model. On ``linear`` and ``ungm`` it does. On the
quadrotor the truth comes from the 16-state simulation flown by a controller, with no process
noise, and the bound is computed with the *filter's* Q and R. There it is the bound the filter's
own model implies, not a bound on the true posterior.

Singular or nearly singular Q (condition number above 1e12): ``Q⁻¹`` is formed from ``Q + δ I``
with ``δ = 1e-12 · max(diag Q)`` (documented regularisation). A well-conditioned Q, as in every
shipped model, is inverted exactly. The information form loses about cond(Q)·eps: on the
constant-velocity model it matches the Kalman covariance to ~1e-13 at T = 0.1 s (cond(Q) ≈ 1e3)
and to ~1e-9 at T = 0.01 s (cond(Q) ≈ 1e5).
"""

from __future__ import annotations

import numpy as np

from quadest.montecarlo import MonteCarloData

REGULARISATION = 1e-12


def _inverse_noise(M: np.ndarray) -> np.ndarray:
    if np.linalg.cond(M) <= 1.0 / REGULARISATION:
        return np.linalg.inv(M)
    delta = REGULARISATION * float(np.max(np.diag(M)))
    return np.linalg.inv(M + delta * np.eye(M.shape[0]))


def pcrlb_variances(data: MonteCarloData, P0: np.ndarray | None = None) -> np.ndarray:
    """``diag(J_k⁻¹)`` for k = 0..K (K+1, n), with expectations over the runs of ``data``.

    ``P0`` defaults to ``data.P0``. Uses the model's analytic Jacobians where it has them and
    central differences otherwise; inputs carry the *true* companion values (thesis angles).
    """
    model = data.model
    K1, n = data.truth.shape[1:]
    P0 = data.P0 if P0 is None else P0
    Qi, Ri = _inverse_noise(model.Q), _inverse_noise(model.R)
    J = np.linalg.inv(P0)
    out = np.empty((K1, n))
    out[0] = np.diag(P0)
    u_prev = model.filter_input(data.inputs[:, 0], data.companion_truth[:, 0])
    for k in range(1, K1):
        u_now = model.filter_input(data.inputs[:, k], data.companion_truth[:, k])
        F = model.F(data.truth[:, k - 1], u_prev)
        H = model.H(data.truth[:, k], u_now)
        Ft = np.swapaxes(F, -1, -2)
        D11 = (Ft @ Qi @ F).mean(axis=0)
        D12 = -Ft.mean(axis=0) @ Qi
        D22 = Qi + (np.swapaxes(H, -1, -2) @ Ri @ H).mean(axis=0)
        J = D22 - D12.T @ np.linalg.solve(J + D11, D12)
        J = 0.5 * (J + J.T)
        out[k] = np.diag(np.linalg.inv(J))
        u_prev = u_now
    return out
