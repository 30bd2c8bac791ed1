"""The Gaussian predict and update steps (:mod:`quadest.estimators.gaussian_steps`) against
independent references: filterpy's linear Kalman filter, the closed-form moments of a linear map,
an explicit matrix inverse. Every case has a correlated non-identity covariance and a partially
observed state (m < n), and runs on two leading batch axes (runs × particles), as the EKPF and UPF
use them.

Tolerances come from round-off: a product of well-conditioned matrices of size ≤ 6 loses a few
ulps, so 1e-12 relative; a sigma-point rule sums ``L`` terms weighted up to ``max |w|`` (1e6 at
α = 1e-3) whose cancellation costs ``L · max |w|`` ulps, and its tolerance is that many.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from quadest.conformance import linear_gaussian_problem
from quadest.estimators.gaussian_steps import (
    covariance_posterior,
    joseph_covariance,
    kalman_correction,
    linearized_covariance,
    linearized_moments,
    point_mean,
    sigma_point_covariance,
    sigma_point_moments,
    sigma_points,
)
from quadest.estimators.particle_ekpf import EKPF
from quadest.numerics.huber import HuberSettings
from quadest.numerics.rules import (
    CentralDifferenceRule,
    CubatureRule,
    FifthDegreeCubatureRule,
    GaussHermiteRule,
    UnscentedRule,
)

N, M = 5, 2  # state and measurement dimensions: the state is partially observed
BATCH = (3, 4)  # runs × particles


def spd(rng: np.random.Generator, n: int, scale: float, batch: tuple[int, ...] = ()) -> np.ndarray:
    A = rng.standard_normal((*batch, n, n))
    return scale * (A @ np.swapaxes(A, -1, -2) / n + 0.3 * np.eye(n))


@pytest.fixture
def problem():
    rng = np.random.default_rng(11)
    return {
        "F": np.eye(N) + 0.1 * rng.standard_normal((N, N)),
        "H": rng.standard_normal((M, N)),
        "Q": spd(rng, N, 0.05),
        "R": spd(rng, M, 0.2),
        "x": rng.standard_normal((*BATCH, N)),
        "P": spd(rng, N, 1.0, BATCH),
        "z": rng.standard_normal((*BATCH, M)),
    }


def filterpy_cycle(p: dict, index: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """One predict and update of filterpy's KalmanFilter (Joseph form) for one batch entry."""
    kf = KalmanFilter(dim_x=N, dim_z=M)
    kf.x, kf.P = p["x"][index].copy(), p["P"][index].copy()
    kf.F, kf.H, kf.Q, kf.R = p["F"], p["H"], p["Q"], p["R"]
    kf.predict()
    kf.update(p["z"][index])
    return kf.x, kf.P


def test_linearized_steps_are_filterpys_kalman_filter_on_a_linear_model(problem):
    p = problem
    x_pred = p["x"] @ p["F"].T
    P_pred = linearized_covariance(p["F"], p["P"], p["Q"])
    moments = linearized_moments(x_pred @ p["H"].T, p["H"], P_pred, p["R"])
    factor = np.linalg.cholesky(moments.cov)
    conditioned = kalman_correction(p["z"] - moments.mean, moments.cross, factor)
    x_post = x_pred + conditioned.correction
    P_post = joseph_covariance(P_pred, p["H"], p["R"], conditioned.gain)
    for index in np.ndindex(*BATCH):
        x_ref, P_ref = filterpy_cycle(p, index)
        np.testing.assert_allclose(x_post[index], x_ref, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(P_post[index], P_ref, rtol=1e-12, atol=1e-12)
        # for the optimal gain, P − K Pyy Kᵀ is the same posterior
        np.testing.assert_allclose(
            covariance_posterior(P_pred, conditioned.gain, moments.cov)[index], P_ref, rtol=1e-10, atol=1e-12
        )


def test_kalman_correction_is_the_gain_of_the_explicit_inverse(problem):
    rng = np.random.default_rng(5)
    Pyy = spd(rng, M, 1.0, BATCH)
    Pxy = rng.standard_normal((*BATCH, N, M))
    nu = rng.standard_normal((*BATCH, M))
    conditioned = kalman_correction(nu, Pxy, np.linalg.cholesky(Pyy))
    K = Pxy @ np.linalg.inv(Pyy)
    np.testing.assert_allclose(conditioned.gain, K, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(conditioned.correction, (K @ nu[..., None])[..., 0], rtol=1e-12, atol=1e-12)
    assert conditioned.huber is None


def test_the_huber_correction_needs_the_prior_factor_and_is_kalmans_within_the_threshold(problem):
    p = problem
    x, P = p["x"][0], p["P"][0]
    moments = linearized_moments(x @ p["H"].T, p["H"], P, p["R"])
    nu = 1e-3 * (p["z"][0] - moments.mean)  # whitened residuals far inside the threshold
    factor = np.linalg.cholesky(moments.cov)
    settings = HuberSettings(threshold=1.345, max_iterations=50, tolerance=1e-10)
    with pytest.raises(ValueError, match="prior_factor"):
        kalman_correction(nu, moments.cross, factor, settings)
    robust = kalman_correction(nu, moments.cross, factor, settings, np.linalg.cholesky(P))
    plain = kalman_correction(nu, moments.cross, factor)
    assert not robust.huber.robust.any()
    np.testing.assert_array_equal(robust.correction, plain.correction)


RULES = [
    ("ut-1e-3", UnscentedRule(1e-3, 2.0, 0.0)),
    ("ut-0.5", UnscentedRule(0.5, 2.0, 0.0)),
    ("cd", CentralDifferenceRule()),
    ("cubature3", CubatureRule()),
    ("cubature5", FifthDegreeCubatureRule()),
    ("gh3", GaussHermiteRule(3)),
]


@pytest.mark.parametrize("name,rule", RULES, ids=[r[0] for r in RULES])
def test_every_rule_gives_the_exact_moments_of_a_linear_map(problem, name, rule):
    """A rule integrates polynomials of degree ≤ 2 exactly, so for ``y = H x + d + v`` its moments
    are the linearisation's, and for ``f = F x`` its covariance is ``F P Fᵀ + Q``."""
    p = problem
    d = np.array([0.3, -1.2])
    X = sigma_points(rule, p["x"], np.linalg.cholesky(p["P"]))
    wm, wc = rule.weights(N)
    tol = 8 * X.shape[-2] * max(1.0, np.abs(wm).max(), np.abs(wc).max()) * np.finfo(float).eps
    x_mean, DX = point_mean(X, wm)
    np.testing.assert_allclose(x_mean, p["x"], rtol=tol, atol=tol)
    y_mean, DY = point_mean(X @ p["H"].T + d, wm)
    moments = sigma_point_moments(rule, DX, DY, N, y_mean, p["R"])
    exact = linearized_moments(p["x"] @ p["H"].T + d, p["H"], p["P"], p["R"])
    scale = np.abs(exact.cov).max()
    np.testing.assert_allclose(moments.mean, exact.mean, rtol=tol, atol=tol * scale)
    np.testing.assert_allclose(moments.cov, exact.cov, rtol=tol, atol=tol * scale)
    np.testing.assert_allclose(moments.cross, exact.cross, rtol=tol, atol=tol * scale)
    _, DF = point_mean(X @ p["F"].T, wm)
    np.testing.assert_allclose(
        sigma_point_covariance(rule, DF, N, p["Q"]),
        linearized_covariance(p["F"], p["P"], p["Q"]),
        rtol=tol,
        atol=tol * scale,
    )


def test_points_on_a_manifold_use_its_boxplus_and_the_mean_its_boxminus():
    """On the circle (angles wrapped to (−π, π]) points about a mean near π wrap, and the mean and
    deviations through ⊞/⊟ are the unwrapped ones."""

    def wrap(a):
        return (a + np.pi) % (2 * np.pi) - np.pi

    def boxplus(x, d):
        return wrap(x + d)

    def boxminus(y, x):
        return wrap(y - x)

    rule = UnscentedRule(1.0, 2.0, 0.0)
    x, S = np.array([[np.pi - 0.05]]), np.array([[[0.2]]])
    X = sigma_points(rule, x, S, boxplus)
    assert X.max() <= np.pi and X.min() < 0  # one point wrapped
    mean, D = point_mean(X, rule.weights(1)[0], boxplus, boxminus)
    np.testing.assert_allclose(mean, x, atol=1e-15)
    np.testing.assert_allclose(D, sigma_points(rule, np.zeros((1, 1)), S), atol=1e-15)


@pytest.mark.slow
def test_ekpf_proposal_is_filterpys_kalman_step_from_every_particle():
    """The EKPF's proposal (μ_i, P̂_i) is one Kalman step from each particle's (x_i, P_i) with the
    proposal's own Q and R: filterpy's KalmanFilter, particle by particle."""
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=2, seed=8)
    est = EKPF(model, particles=6, proposal_Q=0.3, proposal_R=0.2)
    est.set_generators([np.random.default_rng(s) for s in (0, 1)])
    est.initialize(x0, P0)
    est.particle_state["P"] *= 1.0 + np.arange(6.0)[None, :, None, None]  # a different P_i per particle
    mu, P_new = est.proposal_moments(u[:, 0], z[:, 1], u[:, 1])
    for b, i in np.ndindex(2, 6):
        kf = KalmanFilter(dim_x=model.n, dim_z=model.m)
        kf.x, kf.P = est.x[b, i].copy(), est.particle_state["P"][b, i].copy()
        kf.F, kf.H, kf.Q, kf.R = model.A, model.C, est.Q_proposal, est.R_proposal  # the model has no input
        kf.predict()
        kf.update(z[b, 1])
        np.testing.assert_allclose(mu[b, i], kf.x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(P_new[b, i], kf.P, rtol=1e-12, atol=1e-12)
