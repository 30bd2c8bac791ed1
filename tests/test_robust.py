"""The Huber measurement update (quadest.numerics.huber) and the robust filters built on it: hf,
huber_ckf, hhcf and ``robust: true`` on every sigma-point filter (srukf, ckf, srckf, ckf5, srckf5, cdkf,
srcdkf, dd1, ghkf).

- As γ → ∞ each Huber filter is its parent: bit for bit for the sigma-point filters (no residual
  exceeds γ, so every run keeps the parent's update, computed by the parent's code); to round-off
  for ``hf`` against filterpy's EKF (same equations, filterpy inverts ``S`` where ``hf`` solves).
- One Huber update equals statsmodels' RLM with HuberT(t = γ) and unit scale on the whitened
  regression built here from R, P and H (not from the filter's Pxy and Pyy).
- On a linear-Gaussian model, where the Kalman filter is optimal, a Huber filter's RMSE is within a
  few percent of its parent's; with 10 % of 100× outliers it is clearly lower. Margins come from
  the spread of the paired per-run differences (standard error of their mean).
"""

from __future__ import annotations

import numpy as np
import pytest
import statsmodels.api as sm

from helpers import compose_config, compose_settings, random_spd, run_filter, simulate, smooth_model
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.estimators.central_difference import CDKF, SRCDKF
from quadest.estimators.cubature import CKF, CKF5, SRCKF, SRCKF5
from quadest.estimators.divided_difference import DD1
from quadest.estimators.extended import HuberEKF
from quadest.estimators.filterpy_ekf import BatchedFilterpyEKF
from quadest.estimators.gauss_hermite import GHKF
from quadest.estimators.huber import HHCF, HuberCKF
from quadest.estimators.srukf import SRUKF
from quadest.models.base import MeasurementModel
from quadest.models.functional import LinearGaussianModel
from quadest.numerics.huber import HuberSettings, huber_update
from quadest.numerics.square_root import kalman_gain
from quadest.sensors.noise_laws import NoiseLaw, draw_noise
from quadest.simulation.quadrotor_data import build_quadrotor_data

INF = 1e12  # γ beyond any whitened residual
FAMILY = {
    "ckf": CKF,
    "srckf": SRCKF,
    "ckf5": CKF5,
    "srckf5": SRCKF5,
    "cdkf": CDKF,
    "srcdkf": SRCDKF,
    "dd1": DD1,
    "ghkf": GHKF,
    "srukf": SRUKF,
}
PAIRS = {  # Huber filter and its parent
    "huber_ckf": (lambda m: HuberCKF(m, huber_threshold=INF), CKF),
    "hhcf": (lambda m: HHCF(m, huber_threshold=INF), CKF5),
    **{name: (lambda m, c=cls: c(m, robust=True, huber_threshold=INF), cls) for name, cls in FAMILY.items()},
}


@pytest.mark.parametrize("pair", PAIRS.values(), ids=PAIRS.keys())
def test_with_infinite_threshold_a_huber_sigma_point_filter_is_its_parent_bit_for_bit(pair):
    huber, parent = pair
    model = smooth_model(3, n=4, m=2, batch_size=3)
    P0 = np.broadcast_to(random_spd(np.random.default_rng(1), 4, 0.2), (3, 4, 4))
    x_true, u, z = simulate(model, np.zeros((3, 4)), 60, seed=2)
    x0 = x_true[:, 0] + 0.1
    a = run_filter(huber(model), model, x0, P0, u, z)
    b = run_filter(parent(model), model, x0, P0, u, z)
    for got, ref in zip(a, b, strict=True):
        assert np.array_equal(got, ref)


def test_with_infinite_threshold_hf_is_filterpys_ekf_on_the_thesis_quadrotor():
    data = build_quadrotor_data(compose_settings(["runs=2", "duration=1.0"]))
    m = data.model
    u = np.stack([m.filter_input(data.inputs[:, k], data.companion_truth[:, k]) for k in range(data.time.size)], 1)
    P0 = np.broadcast_to(data.P0, (2, m.n, m.n))
    a = run_filter(HuberEKF(m, huber_threshold=INF), m, data.x0, P0, u, data.measurements)
    b = run_filter(BatchedFilterpyEKF(m), m, data.x0, P0, u, data.measurements)
    for got, ref in zip(a, b, strict=True):  # round-off: filterpy inverts S, hf solves with its factor
        assert np.abs(got - ref).max() <= 1e-9 * np.abs(ref).max()


def _update_problem(seed: int, B: int = 4, n: int = 4, m: int = 3):
    """Prior P, measurement matrix H, noise R and innovations with one gross outlier per run."""
    rng = np.random.default_rng(seed)
    P = np.stack([random_spd(rng, n) for _ in range(B)])
    R = np.stack([random_spd(rng, m, 0.5) for _ in range(B)])
    H = rng.standard_normal((B, m, n))
    S = H @ P @ np.swapaxes(H, -1, -2) + R
    nu = (np.linalg.cholesky(S) @ rng.standard_normal((B, m, 1)))[..., 0]
    nu[:, 0] += 15.0 * np.sqrt(R[:, 0, 0])
    return P, R, H, nu


def test_one_huber_update_equals_statsmodels_rlm_on_the_whitened_regression():
    gamma = 1.345
    P, R, H, nu = _update_problem(5)
    B = P.shape[0]
    Pxy, Pyy = P @ np.swapaxes(H, -1, -2), H @ P @ np.swapaxes(H, -1, -2) + R
    Sy, Lp = np.linalg.cholesky(Pyy), np.linalg.cholesky(P)
    kalman = (kalman_gain(Pxy, Sy) @ nu[..., None])[..., 0]
    step = huber_update(nu, Pxy, Sy, Lp, kalman, HuberSettings(gamma, 1000, 1e-13))
    assert step.robust.all()
    for i in range(B):
        delta, cov = _rlm(R[i], P[i], H[i], nu[i], gamma)
        assert np.abs(step.correction[i] - delta).max() <= 1e-8 * np.abs(delta).max()
        assert np.abs(step.factor[i] @ step.factor[i].T - cov).max() <= 1e-8 * np.abs(cov).max()
        assert not np.allclose(step.correction[i], kalman[i], rtol=1e-3)  # the outlier did move it


def _rlm(R: np.ndarray, P: np.ndarray, H: np.ndarray, nu: np.ndarray, gamma: float):
    """statsmodels' Huber fit (unit scale) of the whitened regression and ``(MᵀWM)⁻¹`` at its final weights."""
    Lr_inv, Lp_inv = np.linalg.inv(np.linalg.cholesky(R)), np.linalg.inv(np.linalg.cholesky(P))
    y = np.concatenate([Lr_inv @ nu, np.zeros(P.shape[0])])
    M = np.vstack([Lr_inv @ H, Lp_inv])
    fit = sm.RLM(y, M, M=sm.robust.norms.HuberT(t=gamma)).fit(
        maxiter=1000, tol=1e-13, conv="coefs", start_scale=1.0, update_scale=False
    )
    return fit.params, np.linalg.inv(M.T @ (fit.weights[:, None] * M))


ROBUST = {
    "huber_ckf": lambda m, **kw: HuberCKF(m, **kw),
    "hhcf": lambda m, **kw: HHCF(m, **kw),
    "hf": lambda m, **kw: HuberEKF(m, **kw),
    **{name: (lambda m, c=cls, **kw: c(m, robust=True, **kw)) for name, cls in FAMILY.items()},
}


@pytest.mark.parametrize("make", ROBUST.values(), ids=ROBUST.keys())
def test_a_filters_huber_update_is_the_m_estimate_and_its_covariance(make):
    """On a linear measurement the filter's update is the regression's: mean and covariance (every
    rule integrates the linear measurement exactly, so the moments are the Kalman filter's)."""
    model = _constant_velocity(1)
    x0, P0 = np.array([[0.3, -0.2, 0.1, 0.05]]), random_spd(np.random.default_rng(4), 4)[None]
    z = np.array([[5.0, -0.4]])  # an outlier in the first component (σ = 0.5)
    est = make(model, huber_max_iterations=1000, huber_tolerance=1e-13)
    est.initialize(x0, P0)
    est.update(z, np.zeros((1, 0)))
    delta, P = _rlm(model.R, P0[0], model.C, z[0] - model.C @ x0[0], 1.345)
    assert np.abs(est.mean[0] - x0[0] - delta).max() <= 1e-8 * np.abs(delta).max()
    assert np.abs(est.covariance[0] - P).max() <= 1e-8 * np.abs(P).max()
    assert est.diagnostics()["huber_robust_fraction"][0] == 1.0


def test_huber_ckf_is_the_ckf_with_robust_true():
    model = _constant_velocity(2)
    rng = np.random.default_rng(8)
    z = rng.standard_normal((2, 40, 2)) * np.where(rng.random((2, 40, 1)) < 0.2, 10.0, 0.5)
    P0 = np.broadcast_to(np.eye(4), (2, 4, 4))
    a = run_filter(HuberCKF(model, huber_threshold=2.0), model, np.zeros((2, 4)), P0, np.zeros((2, 40, 0)), z)
    b = run_filter(CKF(model, robust=True, huber_threshold=2.0), model, np.zeros((2, 4)), P0, np.zeros((2, 40, 0)), z)
    for got, ref in zip(a, b, strict=True):
        assert np.array_equal(got, ref)


@pytest.mark.parametrize("make", ROBUST.values(), ids=ROBUST.keys())
def test_updates_without_measurement_rows_do_not_count_in_the_huber_fractions(make):
    """An INS-like model: an empty primary measurement (m = 0) every step, positions as a named
    sensor. One empty update and one outlying position update: one update measured something,
    and it was robust, so the robust fraction is 1 (it was 1/2 when empty updates counted)."""
    cv = _constant_velocity(1)
    model = LinearGaussianModel(cv.A, np.zeros((0, 4)), cv.Q, np.zeros((0, 0)), dt=cv.dt, batch_size=1)
    model.sensors = {"position": MeasurementModel(lambda x, u: x[..., :2], cv.R, ("x", "y"))}
    est = make(model)
    est.initialize(np.zeros((1, 4)), np.eye(4)[None])
    est.update(np.zeros((1, 0)), np.zeros((1, 0)))
    est.update(np.array([[5.0, -0.4]]), np.zeros((1, 0)), sensor="position")
    assert est.diagnostics()["huber_robust_fraction"][0] == 1.0


def _constant_velocity(B: int) -> LinearGaussianModel:
    dt = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    G = np.array([[dt**2 / 2, 0], [0, dt**2 / 2], [dt, 0], [0, dt]])
    return LinearGaussianModel(A, np.eye(2, 4), 0.5 * G @ G.T + 1e-9 * np.eye(4), 0.25 * np.eye(2), dt=dt, batch_size=B)


def _paired_rmse(huber, parent, law: NoiseLaw, B: int = 300, steps: int = 150):
    """Per-run position RMSE (after 20 steps) of both filters on the same runs; the measurement
    noise follows ``law`` at the nominal σ = 0.5 the filters assume."""
    model = _constant_velocity(B)
    rng = np.random.default_rng(11)
    P0 = np.diag([1.0, 1.0, 0.25, 0.25])
    x = np.empty((B, steps + 1, 4))
    x[:, 0] = rng.standard_normal((B, 4)) @ np.linalg.cholesky(P0).T
    LQ = np.linalg.cholesky(model.Q)
    for k in range(steps):
        x[:, k + 1] = x[:, k] @ model.A.T + rng.standard_normal((B, 4)) @ LQ.T
    z = x[..., :2] + np.stack([draw_noise(law, np.random.default_rng([12, i]), (steps + 1, 2), 0.5) for i in range(B)])
    u = np.zeros((B, steps + 1, 0))
    rmse = []
    for est in (huber(model), parent(model)):
        means, _ = run_filter(est, model, np.zeros((B, 4)), np.broadcast_to(P0, (B, 4, 4)), u, z)
        err = means[19:, :, :2] - np.swapaxes(x[:, 20:, :2], 0, 1)
        rmse.append(np.sqrt((err**2).sum(-1).mean(0)))
    return rmse


def _relative_difference(huber_rmse, parent_rmse):
    """Mean paired difference over the parent's mean RMSE, and its standard error."""
    d = huber_rmse - parent_rmse
    return d.mean() / parent_rmse.mean(), d.std(ddof=1) / np.sqrt(d.size) / parent_rmse.mean()


LINEAR_PAIRS = [
    (lambda m: HuberCKF(m), CKF),
    (lambda m: SRUKF(m, robust=True), SRUKF),
    (lambda m: HuberEKF(m), BatchedFilterpyEKF),
]


@pytest.mark.parametrize("pair", LINEAR_PAIRS, ids=["huber_ckf", "srukf", "hf"])
@pytest.mark.slow
def test_huber_costs_a_few_percent_under_gaussian_noise_and_pays_under_outliers(pair):
    huber, parent = pair
    rel, se = _relative_difference(*_paired_rmse(huber, parent, NoiseLaw("gaussian")))
    # The parent is the optimal (Kalman) filter here; Huber's γ = 1.345 has 95 % efficiency, about
    # +2.6 % RMSE for a location problem: allow 5 % plus three standard errors.
    assert -3 * se < rel < 0.05 + 3 * se
    rel, se = _relative_difference(
        *_paired_rmse(huber, parent, NoiseLaw("contaminated", epsilon=0.1, variance_factor=100.0))
    )
    assert rel < -0.15 and rel < -3 * se


def test_huber_iterations_reach_the_diagnostics():
    model = _constant_velocity(5)
    est = HuberCKF(model, huber_max_iterations=7)
    law = NoiseLaw("contaminated", epsilon=0.2, variance_factor=100.0)
    z = np.stack([draw_noise(law, np.random.default_rng([3, i]), (80, 2), 0.5) for i in range(5)])
    run_filter(est, model, np.zeros((5, 4)), np.broadcast_to(np.eye(4), (5, 4, 4)), np.zeros((5, 80, 0)), z)
    d = est.diagnostics()
    assert set(d) >= {"huber_iterations_mean", "huber_iterations_max", "huber_robust_fraction"}
    assert np.all(d["huber_iterations_max"] >= 1) and np.all(d["huber_iterations_max"] <= 7)
    assert np.all((d["huber_robust_fraction"] > 0) & (d["huber_robust_fraction"] <= 1))
    assert CKF(model).diagnostics() == {}


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("estimator.huber_ckf.huber_threshold=0", "estimator.huber_ckf.huber_threshold"),
        ("estimator.huber_ckf.huber_max_iterations=0", "estimator.huber_ckf.huber_max_iterations"),
        ("estimator.huber_ckf.huber_tolerance=-1", "estimator.huber_ckf.huber_tolerance"),
    ],
)
def test_bad_huber_settings_are_one_config_error(override, key):
    with pytest.raises(ConfigError) as err:
        validate(compose_config(["estimator=[huber_ckf]", override]))
    assert err.value.key == key
