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
On ``linear``, ``ungm`` and ``seed001_rates`` with its default ``model.truth=own_model`` (rates driven
by the filter model's own process noise) it does:
the truth is drawn from the filter model with its own Q and R, so the recursion is a bound and
the tests hold every filter to it within Monte Carlo error. On the quadrotor it does not: the
truth is the 16-state simulation flown by a controller, with no process noise, and measured by
sensors whose errors the filter only approximates by R; the recursion evaluated there with the
filter's Q and R is *not* a bound (the SR-UKF's pooled MSE of vx, vy is about 0.6 of it with 20
runs of 3 s). It is reported as a reference for the filter model, and every table caption says
so (:func:`pcrlb_caption`). A bound for the quadrotor would need the Fisher information of the
true system (deterministic dynamics, per-run sensor errors), which quadest does not compute.

Evaluation: the covariance form. Write ``D11 = F̄ᵀ Q⁻¹ F̄ + C`` with ``F̄ = E[F]`` and
``C = E[(F − F̄)ᵀ Q⁻¹ (F − F̄)]`` (the Jacobians' spread over the runs). The matrix inversion
lemma turns the recursion above into

    P̃ = (P_{k−1}⁻¹ + C)⁻¹,   P⁻ = F̄ P̃ F̄ᵀ + Q,   P_k = J_k⁻¹ = (P⁻⁻¹ + E[Hᵀ R⁻¹ H])⁻¹

the same numbers (to round-off) wherever ``Q`` is invertible, and with a deterministic ``F`` (a
linear model) exactly the Kalman filter's Riccati recursion. Both information additions are done
as Joseph-form updates with a pseudo-measurement ``Lᵀ x``, ``L Lᵀ`` the information
(:func:`add_information`), so nothing but the measurement noise ``R`` is inverted, and every
``P_k`` is symmetric positive semi-definite to round-off. ``Q`` enters ``P⁻`` as it is, so a
singular ``Q`` (``model=ins``: one acceleration noise drives position and velocity and constant
biases have none, rank 6 of 15 in seed 004's setting) is handled exactly; ``C`` uses ``Q⁺``, the
inverse on ``Q``'s range. The spread outside that range is not counted: it would be infinite
information (the transition has no density there). On ``model=ins`` the spread lies in the range
(the Jacobians vary through the IMU samples and scale factors, which enter as the noise does),
which ``tests/test_pcrlb.py`` checks. ``R`` is inverted exactly when its condition number is at
most 1e12 and from ``R + δ I``, ``δ = 1e-12 · max(diag R)``, otherwise (a nearly exact
measurement).

Averaging: one recursion on expectations over the runs (in Tichavský et al. 1998 the D's are
expectations over the joint density of states and measurements), not the mean of per-run
recursions. With
Jacobians that differ from run to run (UNGM's state, the INS's IMU samples and per-run scale
factors), ``C`` is information the averaged recursion has and no single run has: the bound stays a
bound where the truth follows the filter model (it is the Bayesian information of the ensemble,
Van Trees 1968), but it is looser than the mean of the per-run Riccati covariances and can shrink
at a step without a measurement. On seed 004's landing the gyro noise is tiny (``Q`` of the
attitude 8.5e-12 rad² per step), so this spread makes the y and z position bounds a sixth to a quarter
of what the mean Jacobian alone gives (docs/ins.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from quadest.montecarlo import MonteCarloData
from quadest.simulation.registry import model_specs

REGULARISATION = 1e-12  # of R only (module docstring)


def pcrlb_is_bound(model_name: str, labels: Mapping[str, Any] | None = None) -> bool:
    """Whether the PCRLB of ``model=<model_name>`` bounds the filters' MSE (see the module
    docstring): what the option's :class:`~quadest.simulation.spec.ModelSpec` declares
    (``pcrlb_is_bound``: its truth is drawn from the filter model with its own noise), or, where
    the spec declares it as a function of the data's ``labels``, what it says of these (``False``
    without labels); ``False`` for a name no model is registered under."""
    spec = model_specs().get(model_name)
    if spec is None:
        return False
    if callable(spec.pcrlb_is_bound):
        return labels is not None and bool(spec.pcrlb_is_bound(labels))
    return bool(spec.pcrlb_is_bound)


SMOOTHED_NOTE = (
    " It is the filtering bound (measurements up to each step): a smoothed row also uses the later ones, so its "
    "own bound is lower and it may go below this column."
)


def pcrlb_caption(model_name: str, smoothed: bool = False, labels: Mapping[str, Any] | None = None) -> str:
    """The line printed under the RMSE table that says what its PCRLB column is (``labels``: the
    data's, for a model whose truth is a setting, :func:`pcrlb_is_bound`); with ``smoothed``
    (the table has smoothed rows), that the column is the filtering bound, not the smoothers' (their
    Fisher information adds the later measurements', so their bound is lower; Tichavský, Muravchik &
    Nehorai 1998 give the filtering recursion)."""
    if pcrlb_is_bound(model_name, labels):
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


def _eigen_range(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues and eigenvectors of the symmetric positive semi-definite ``M`` on its range, the
    rank decided as :func:`numpy.linalg.matrix_rank` decides it (eigenvalues above
    ``λ_max · n · eps``; the rest are round-off)."""
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    kept = w > max(float(w.max()), 0.0) * M.shape[0] * np.finfo(float).eps
    return w[kept], V[:, kept]


def range_inverse(Q: np.ndarray) -> np.ndarray:
    """``Q⁺``: the inverse of ``Q`` on its range (``Q⁻¹`` for a non-singular ``Q``)."""
    w, V = _eigen_range(Q)
    return (V / w) @ V.T


def _factor(info: np.ndarray) -> np.ndarray:
    """``L`` (n, r) with ``L Lᵀ = info`` on the range of ``info`` (:func:`_eigen_range`)."""
    w, V = _eigen_range(info)
    return V * np.sqrt(w)


def add_information(P: np.ndarray, info: np.ndarray) -> np.ndarray:
    """``(P⁻¹ + info)⁻¹`` without inverting ``P``: a Kalman update with the pseudo-measurement
    ``Lᵀ x`` of unit noise (``L Lᵀ = info``), in Joseph form (Bucy & Joseph 1968), so the result
    is symmetric positive semi-definite to round-off whatever the conditioning of ``P``."""
    L = _factor(info)
    if L.shape[1] == 0:
        return P
    PL = P @ L
    K = np.linalg.solve(np.eye(L.shape[1]) + L.T @ PL, PL.T).T
    A = np.eye(P.shape[0]) - K @ L.T
    out = A @ P @ A.T + K @ K.T
    return 0.5 * (out + out.T)


def pcrlb_variances(data: MonteCarloData, P0: np.ndarray | None = None) -> np.ndarray:
    """``diag(J_k⁻¹)`` for k = 0..K (K+1, n), with expectations over the runs of ``data``.

    ``P0`` defaults to ``data.P0``. Uses the model's analytic Jacobians where it has them and
    central differences otherwise; inputs carry the *true* companion values (thesis angles). The
    recursion is the module docstring's covariance form: ``Q`` is never inverted off its range.
    """
    model = data.model
    K1, n = data.truth.shape[1], model.n_err
    P0 = data.P0 if P0 is None else P0
    Q_range_inverse = range_inverse(model.Q)
    measured = [(None, _inverse_noise(model.R) if model.m else None, np.ones(K1, dtype=bool))]
    measured += [(name, _inverse_noise(model.measurement(name).R), rec.available) for name, rec in data.sensors.items()]
    P = np.array(P0, dtype=float)
    out = np.empty((K1, n))
    out[0] = np.diag(P)
    u_prev = model.filter_input(data.inputs[:, 0], data.companion_truth[:, 0])
    for k in range(1, K1):
        u_now = model.filter_input(data.inputs[:, k], data.companion_truth[:, k])
        F = model.F_err(data.truth[:, k - 1], u_prev)  # = F, H for vector states
        F_mean = F.mean(axis=0)
        spread = F - F_mean
        spread_t = np.swapaxes(spread, -1, -2)
        prior = add_information(P, (spread_t @ Q_range_inverse @ spread).mean(axis=0))
        P = F_mean @ prior @ F_mean.T + model.Q
        info = np.zeros((n, n))
        for sensor, Ri, available in measured:
            if Ri is not None and available[k]:
                H = model.H_err(data.truth[:, k], u_now, sensor)
                info += (np.swapaxes(H, -1, -2) @ Ri @ H).mean(axis=0)
        P = add_information(0.5 * (P + P.T), info)
        out[k] = np.diag(P)
        u_prev = u_now
    return out
