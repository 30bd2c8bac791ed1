"""The posterior Cramér–Rao recursion (quadest.evaluation.pcrlb) against closed forms: the Kalman
filter's Riccati recursion with a singular Q, Tichavský's information form where Q is invertible,
and the properties any bound has (monotone in P0, no negative variance, no information from a step
without a measurement, the measurement at step k read with the input of step k, the transition
into step k with the input of step k − 1)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from helpers import compose_settings
from quadest.evaluation.metrics import rmse_table
from quadest.evaluation.pcrlb import pcrlb_variances
from quadest.simulation.registry import build_data

EPS = np.finfo(float).eps


def riccati(A, Q, P0, H_of_step, R) -> np.ndarray:
    """diag P_k of the Kalman filter's covariance (standard form, not the Joseph form the bound
    uses): ``P⁻ = A P Aᵀ + Q``, ``K = P⁻Hᵀ(H P⁻ Hᵀ + R)⁻¹``, ``P = (I − K H) P⁻``; ``A`` is one matrix,
    or a list whose ``A[k − 1]`` leads into step k."""
    steps = len(H_of_step)
    P, out = P0.copy(), [np.diag(P0)]
    for k in range(1, steps):
        A_k = A[k - 1] if isinstance(A, list) else A  # a list: the transition from step k - 1
        P = A_k @ P @ A_k.T + Q
        H = H_of_step[k]
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        P = (np.eye(len(P)) - K @ H) @ P
        P = 0.5 * (P + P.T)
        out.append(np.diag(P))
    return np.array(out)


def double_integrator_Q(T: float, q: float) -> np.ndarray:
    """Acceleration noise through its input matrix ``G = [T²/2, T]`` per axis of the constant-velocity
    model (state ``[x, y, vx, vy]``): ``Q = q G Gᵀ``, rank 2 of 4."""
    Q = np.zeros((4, 4))
    g = np.array([T**2 / 2.0, T])
    for axis in (0, 1):
        idx = [axis, axis + 2]
        Q[np.ix_(idx, idx)] = q * np.outer(g, g)
    return Q


@pytest.fixture(scope="module")
def singular_linear():
    data = build_data(compose_settings(["model=linear", "runs=5", "duration=30.0", "sample_period=0.1"]))
    model = data.model
    Q = double_integrator_Q(model.dt, 1.0)
    assert np.linalg.matrix_rank(Q) == 2
    model = type(model)(model.A, model.C, Q, model.R, dt=model.dt, batch_size=model.batch_size)
    return replace(data, model=model)


def test_with_a_rank_deficient_Q_the_bound_is_the_kalman_covariance(singular_linear):
    """A linear-Gaussian model has a deterministic F and H, so the bound is exactly the Kalman
    filter's Riccati recursion, singular Q or not. Both evaluate the same recursion in a different
    order of operations over 300 steps of a stable filter: relative agreement to 1e-9 (round-off,
    which the filter's contraction keeps from accumulating)."""
    d = singular_linear
    steps = d.truth.shape[1]
    expected = riccati(d.model.A, d.model.Q, d.P0, [d.model.C] * steps, d.model.R)
    bound = pcrlb_variances(d)
    assert np.abs(bound - expected).max() / np.abs(expected).max() <= 1e-9


class InputMeasured:
    """A double integrator whose position is measured with the gain of the current input,
    ``z_k = u_k x_k + n``: ``u_k = 0`` is a step without a measurement. Duck-types what
    :func:`pcrlb_variances` reads of a model."""

    n_err, m = 2, 1

    def __init__(self, T: float, q: float, r: float) -> None:
        self.A = np.array([[1.0, T], [0.0, 1.0]])
        g = np.array([T**2 / 2.0, T])
        self.Q = q * np.outer(g, g)  # rank 1
        self.R = np.array([[r]])

    def filter_input(self, u, companion):
        return u

    def F_err(self, x, u):
        return np.broadcast_to(self.A, (x.shape[0], 2, 2))

    def H_err(self, x, u, sensor=None):
        H = np.zeros((x.shape[0], 1, 2))
        H[:, 0, 0] = u[:, 0]
        return H


def input_measured_data(gains: np.ndarray, runs: int = 3):
    model = InputMeasured(T=0.1, q=0.5, r=0.04)
    K1 = gains.size
    return SimpleNamespace(
        model=model,
        truth=np.zeros((runs, K1, 2)),
        inputs=np.broadcast_to(gains[None, :, None], (runs, K1, 1)),
        companion_truth=np.zeros((runs, K1, 0)),
        sensors={},
        P0=np.diag([4.0, 1.0]),
    )


GAINS = np.tile([1.0, 0.0, 0.0, 2.0, 0.0, 0.5, 0.0, 0.0, 0.0, 3.0], 20)


def test_the_measurement_at_step_k_is_read_with_the_input_of_step_k():
    """``H_k = [u_k, 0]`` changes from step to step: the bound equals the Riccati recursion with
    ``H`` at each step's own input; reading it with ``u_{k−1}`` would not."""
    d = input_measured_data(GAINS)
    m = d.model
    expected = riccati(m.A, m.Q, d.P0, [np.array([[u, 0.0]]) for u in GAINS], m.R)
    assert np.abs(pcrlb_variances(d) - expected).max() / expected.max() <= 1e-9


class InputDriven(InputMeasured):
    """The same double integrator with the velocity entering the position through the input,
    ``x_k = x_{k−1} + u_{k−1} T v_{k−1}`` (F changes from step to step), and the position measured
    at every step with gain 1."""

    def F_err(self, x, u):
        F = np.array(np.broadcast_to(self.A, (x.shape[0], 2, 2)))
        F[:, 0, 1] *= u[:, 0]
        return F

    def H_err(self, x, u, sensor=None):
        return np.broadcast_to(np.array([[1.0, 0.0]]), (x.shape[0], 1, 2))


def test_the_transition_into_step_k_is_read_with_the_input_of_step_k_minus_1():
    """``F_{k−1} = [[1, u_{k−1} T], [0, 1]]``: the bound equals the Riccati recursion with each
    transition at the input of the step it leaves (as the filters predict from k − 1 to k);
    a transition read at another step's input would not."""
    d = input_measured_data(GAINS)
    d.model = m = InputDriven(T=0.1, q=0.5, r=0.04)
    transitions = [np.array([[1.0, u * 0.1], [0.0, 1.0]]) for u in GAINS]
    expected = riccati(transitions, m.Q, d.P0, [np.array([[1.0, 0.0]])] * GAINS.size, m.R)
    assert np.abs(pcrlb_variances(d) - expected).max() / expected.max() <= 1e-9


def test_a_step_without_a_measurement_never_lowers_the_bound():
    """From a diagonal P0, a position measurement keeps cov(x, v) ≥ 0 (it scales it by 1 − K_x), so
    a step without one (``u_k = 0``) adds ``2T cov + T² var v + Q ≥ 0`` to the position variance and
    ``Q ≥ 0`` to the velocity's: neither may go down there, beyond round-off (rank-1 Q)."""
    bound = pcrlb_variances(input_measured_data(GAINS))
    unmeasured = np.flatnonzero(GAINS[1:] == 0.0) + 1
    before, after = bound[unmeasured - 1], bound[unmeasured]
    assert (after >= before * (1.0 - 1e3 * EPS)).all()


@pytest.fixture(scope="module")
def seed004():
    return build_data(compose_settings(["experiment=seed004_landing", "runs=4", "duration=2.0"]))


@pytest.mark.slow
def test_the_ins_bound_has_no_negative_or_non_finite_variance(seed004):
    """model=ins: Q has rank 6 of 15 (one acceleration noise drives position and velocity; the
    biases have none). Every variance of the bound is finite and non-negative."""
    assert np.linalg.matrix_rank(seed004.model.Q) == 6
    bound = pcrlb_variances(seed004)
    assert np.isfinite(bound).all() and (bound >= 0).all()


def test_the_bound_grows_with_the_initial_covariance(seed004):
    """P0 ⪯ P0' gives P_k ⪯ P_k' at every step (each stage of the recursion is monotone in P), so no
    variance may drop when P0 grows 25-fold (1 m → 5 m); before the first camera sample the
    position variance must grow by much more than round-off."""
    small, large = pcrlb_variances(seed004), pcrlb_variances(seed004, 25.0 * seed004.P0)
    assert (large >= small * (1.0 - 1e3 * EPS)).all()
    first = np.flatnonzero(seed004.sensors["vision"].available[1:])[0] + 1
    assert (large[1:first, 3:6] > 10.0 * small[1:first, 3:6]).all()


def test_the_ins_jacobians_vary_from_run_to_run_only_inside_the_range_of_Q(seed004):
    """The bound counts the spread of F over the runs with Q⁺ only: exact when the spread lies in
    Q's range. On the INS it does: the bias rows of F are the identity in every run, and the
    position rows vary ½T times as much as the velocity rows, the direction ``[T²/2, T]`` the
    acceleration noise enters through (round-off: 10 eps of the entries)."""
    d, T = seed004, seed004.model.dt
    for k in (1, d.truth.shape[1] // 2):
        F = d.model.F_err(d.truth[:, k - 1], d.model.filter_input(d.inputs[:, k - 1], d.companion_truth[:, k - 1]))
        spread = F - F.mean(axis=0)
        assert np.abs(spread[:, 9:15]).max() <= 10 * EPS
        assert np.abs(spread[:, 3:6] - 0.5 * T * spread[:, 6:9]).max() <= 10 * EPS * np.abs(F).max()


def test_the_covariance_form_is_tichavskys_information_recursion_on_the_ungm():
    """Where Q is invertible the bound is Tichavský et al.'s recursion J = D22 − D12²/(J + D11),
    D11 = E[F²]/Q (not E[F]²/Q: the Jacobians' spread over the runs counts), D12 = −E[F]/Q,
    D22 = 1/Q + E[H²]/R, written out here for the scalar UNGM; agreement to round-off."""
    d = build_data(compose_settings(["model=ungm", "runs=50", "duration=40", "sample_period=1"]))
    m = d.model
    q, r = float(m.Q[0, 0]), float(m.R[0, 0])
    J, expected = 1.0 / float(d.P0[0, 0]), [float(d.P0[0, 0])]
    for k in range(1, d.truth.shape[1]):
        F = m.F_err(d.truth[:, k - 1], d.inputs[:, k - 1])[:, 0, 0]
        H = m.H_err(d.truth[:, k], d.inputs[:, k])[:, 0, 0]
        D11, D12, D22 = np.mean(F**2) / q, -np.mean(F) / q, 1.0 / q + np.mean(H**2) / r
        J = D22 - D12**2 / (J + D11)
        expected.append(1.0 / J)
    assert np.allclose(pcrlb_variances(d)[:, 0], expected, rtol=1e-12, atol=0)


def test_a_pcrlb_cell_without_a_number_says_why():
    """No bare "-": a row that is not a filter state names its quantity, a bound left out for the
    whole job points to its caption, and a negative or non-finite variance is called invalid."""
    rows = [
        ("filter", "x", 0.5, 0.2),
        ("filter", "v", 0.5, np.nan),
        ("derived", "roll", 0.5, np.nan),
    ]
    summary = pd.DataFrame(
        [
            {"estimator": "ekf", "quantity": q, "state": s, "unit": "m", "rmse_mean": m, "rmse_std": 0.1, "pcrlb": b}
            for q, s, m, b in rows
        ]
    )
    printed = rmse_table(summary)
    assert dict(zip(printed["state"], printed["PCRLB"], strict=True)) == {
        "x [m]": "0.2",
        "v [m]": "invalid: negative or non-finite variance",
        "roll [m]": "n/a: derived quantity",
    }
    left_out = rmse_table(summary.assign(pcrlb=np.nan))
    assert list(left_out["PCRLB"]) == ["left out (caption)", "left out (caption)", "n/a: derived quantity"]
