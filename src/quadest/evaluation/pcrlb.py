"""Posterior Cramér–Rao lower bound (Tichavský, Muravchik & Nehorai 1998, IEEE TSP 46(5)).

For additive Gaussian noise, ``x_k = f(x_{k−1}) + v``, ``z_k = h(x_k) + n``, the Fisher
information of the state obeys

    J_k = D22 − D21 (J_{k−1} + D11)⁻¹ D12,      J_0 = P0⁻¹
    D11 = E[Fᵀ Q⁻¹ F],  D12 = D21ᵀ = −E[Fᵀ] Q⁻¹,  D22 = Q⁻¹ + E[Hᵀ R⁻¹ H]

with ``F`` the Jacobian of ``f`` at the true ``x_{k−1}`` and ``H`` that of ``h`` at the true
``x_k``. Expectations are Monte Carlo averages over the runs' true trajectories. A further sensor
(``data.sensors``) adds its ``E[H_sᵀ R_s⁻¹ H_s]`` to ``D22`` at the steps where it has a sample
(independent measurement noises: the information of sequential updates adds). Then
``E[(x̂_k − x_k)(x̂_k − x_k)ᵀ] ⪰ J_k⁻¹`` for any estimator, so ``√diag(J_k⁻¹)`` is a floor on the
RMSE at each step. It is a floor, not a target.

The inequality needs the truth to follow the filter model. Each model option declares whether
its truth does (``pcrlb_is_bound`` of its :class:`~quadest.simulation.spec.ModelSpec`, docs/models.md).
On ``linear``, ``ungm`` and ``seed001_rates`` (rates driven by the filter model's own process noise) it does:
the truth is drawn from the filter model with its own Q and R, so the recursion is a bound and
the tests hold every filter to it within Monte Carlo error. On the quadrotor it does not: the
truth is the 16-state simulation flown by a controller, with no process noise, and measured by
sensors whose errors the filter only approximates by R; the recursion evaluated there with the
filter's Q and R is *not* a bound (the SR-UKF's pooled MSE of vx, vy is about 0.6 of it with 20
runs of 3 s). It is reported as a reference for the filter model, and every table caption says
so (:func:`pcrlb_caption`). A bound for the quadrotor would need the Fisher information of the
true system (deterministic dynamics, per-run sensor errors), which quadest does not compute.

Singular or nearly singular Q (condition number above 1e12): ``Q⁻¹`` is formed from ``Q + δ I``
with ``δ = 1e-12 · max(diag Q)`` (documented regularisation). A well-conditioned Q, as in every
shipped model, is inverted exactly. The information form loses about cond(Q)·eps: on the
constant-velocity model it matches the Kalman covariance to ~1e-13 at T = 0.1 s (cond(Q) ≈ 1e3)
and to ~1e-9 at T = 0.01 s (cond(Q) ≈ 1e5).
"""

from __future__ import annotations

import numpy as np

from quadest.montecarlo import MonteCarloData
from quadest.simulation.registry import model_specs

REGULARISATION = 1e-12


def pcrlb_is_bound(model_name: str) -> bool:
    """Whether the PCRLB of ``model=<model_name>`` bounds the filters' MSE (see the module
    docstring): what the option's :class:`~quadest.simulation.spec.ModelSpec` declares
    (``pcrlb_is_bound``: its truth is drawn from the filter model with its own noise); ``False``
    for a name no model is registered under."""
    spec = model_specs().get(model_name)
    return spec is not None and spec.pcrlb_is_bound


SMOOTHED_NOTE = (
    " It is the filtering bound (measurements up to each step): a smoothed row also uses the later ones, so its "
    "own bound is lower and it may go below this column."
)


def pcrlb_caption(model_name: str, smoothed: bool = False) -> str:
    """The line printed under the RMSE table that says what its PCRLB column is; with ``smoothed``
    (the table has smoothed rows), that the column is the filtering bound, not the smoothers' (their
    Fisher information adds the later measurements', so their bound is lower; Tichavský, Muravchik &
    Nehorai 1998 give the filtering recursion)."""
    if pcrlb_is_bound(model_name):
        caption = (
            "PCRLB: the posterior Cramér-Rao bound (the truth follows the filter model), a floor on the pooled RMSE "
            "(rmse_summary.csv)."
        )
    else:
        caption = (
            f"PCRLB: the posterior Cramér-Rao recursion of the filter model along the true trajectories; on "
            f"model={model_name} the truth does not follow the filter model, so it is a reference, not a bound "
            "(filters can go below it)."
        )
    return caption + (SMOOTHED_NOTE if smoothed else "")


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
    K1, n = data.truth.shape[1], model.n_err
    P0 = data.P0 if P0 is None else P0
    Qi = _inverse_noise(model.Q)
    measured = [(None, _inverse_noise(model.R) if model.m else None, np.ones(K1, dtype=bool))]
    measured += [(name, _inverse_noise(model.measurement(name).R), rec.available) for name, rec in data.sensors.items()]
    J = np.linalg.inv(P0)
    out = np.empty((K1, n))
    out[0] = np.diag(P0)
    u_prev = model.filter_input(data.inputs[:, 0], data.companion_truth[:, 0])
    for k in range(1, K1):
        u_now = model.filter_input(data.inputs[:, k], data.companion_truth[:, k])
        F = model.F_err(data.truth[:, k - 1], u_prev)  # = F, H for vector states
        Ft = np.swapaxes(F, -1, -2)
        D11 = (Ft @ Qi @ F).mean(axis=0)
        D12 = -Ft.mean(axis=0) @ Qi
        D22 = Qi.copy()
        for sensor, Ri, available in measured:
            if Ri is not None and available[k]:
                H = model.H_err(data.truth[:, k], u_now, sensor)
                D22 += (np.swapaxes(H, -1, -2) @ Ri @ H).mean(axis=0)
        J = D22 - D12.T @ np.linalg.solve(J + D11, D12)
        J = 0.5 * (J + J.T)
        out[k] = np.diag(np.linalg.inv(J))
        u_prev = u_now
    return out
