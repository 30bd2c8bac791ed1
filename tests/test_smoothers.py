"""The Gaussian smoothers (:mod:`quadest.estimators.smoothing`) against independent references.

- On a linear-Gaussian model (n = 4 with m = 2: partially observed; correlated non-identity P0,
  Q, R) every Gaussian filter's fixed-interval smoother, in covariance and square-root form and for
  every rule (the UT at α = 1e-3 included), equals filterpy's ``KalmanFilter.rts_smoother`` run on
  filterpy's own filter. Tolerance 1e-9: the two filters agree to round-off, and a smoother over 40
  steps of a stable model adds round-off of the same order; the UT at α = 1e-3 weights points
  by ~1e6, which costs six of the sixteen digits.
- On a nonlinear model, the unscented smoother equals filterpy's ``UnscentedKalmanFilter.rts_smoother``
  given the same filtered sequence and the same points.
- Fixed lag equals the fixed interval on the data up to ``k + lag``; lag 0 is the filter.
- The smoothed covariance never exceeds the filtered one, and the smoothed error is smaller on
  average over runs (a Monte Carlo statement with its own tolerance).
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

from helpers import simulate, smooth_model
from quadest.conformance import linear_gaussian_problem
from quadest.estimators.error_state_ekf import ErrorStateEKF
from quadest.estimators.extended import HuberEKF
from quadest.estimators.filterpy_ekf import BatchedFilterpyEKF
from quadest.estimators.filterpy_ukf import BatchedFilterpyUKF
from quadest.estimators.particle import BootstrapPF
from quadest.estimators.particle_ekpf import EKPF
from quadest.estimators.particle_ilopf import ILOPF
from quadest.estimators.particle_smoothing import ffbsi
from quadest.estimators.particle_upf import UPF
from quadest.estimators.sigma_point import SigmaPointKalmanFilter, SquareRootSigmaPointFilter
from quadest.estimators.smoothing import fixed_lag, rts_backward
from quadest.models.validation import LinearGaussianModel
from quadest.numerics.rules import (
    CentralDifferenceRule,
    CubatureRule,
    FifthDegreeCubatureRule,
    GaussHermiteRule,
    UnscentedRule,
)

RULES = {
    "ut": UnscentedRule(0.5, 2.0, 0.0),
    "ut-1e-3": UnscentedRule(1e-3, 2.0, 0.0),
    "cd": CentralDifferenceRule(),
    "cubature": CubatureRule(),
    "cubature5": FifthDegreeCubatureRule(),
    "gh3": GaussHermiteRule(3),
}
FILTERS = {
    "mekf": lambda model: ErrorStateEKF(model),
    "hf-gamma-inf": lambda model: HuberEKF(model, huber_threshold=1e12),
    **{f"cov-{name}": (lambda model, r=rule: SigmaPointKalmanFilter(model, r)) for name, rule in RULES.items()},
    **{f"sqrt-{name}": (lambda model, r=rule: SquareRootSigmaPointFilter(model, r)) for name, rule in RULES.items()},
    "sqrt-ut-augmented": lambda model: SquareRootSigmaPointFilter(model, UnscentedRule(1.0, 2.0, 0.0), augmented=True),
    "filterpy-ekf": BatchedFilterpyEKF,  # the baselines, filterpy's own filters with our smoother steps
    "filterpy-ukf": lambda model: BatchedFilterpyUKF(model, 0.5, 2.0, 0.0),
    "filterpy-ukf-1e-3": lambda model: BatchedFilterpyUKF(model, 1e-3, 2.0, 0.0),
}


def spread_of(est) -> np.ndarray:
    return est.sqrt_covariance if "sqrt_covariance" in est.capabilities else est.covariance


def covariance_of(spread: np.ndarray, square_root: bool) -> np.ndarray:
    return spread @ np.swapaxes(spread, -1, -2) if square_root else spread


def forward(est, x0, P0, u, z):
    """Filtered means and spreads after each update k = 1..K, and the K − 1 smoother steps
    between them."""
    est.smoothing = True
    est.initialize(x0, P0)
    means, spreads, steps = [], [], []
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        if k > 1:
            steps.append(est.smoother_step)
        est.update(z[:, k], u[:, k])
        means.append(est.mean.copy())
        spreads.append(spread_of(est).copy())
    assert not est.failed.any()
    return means, spreads, steps


def filterpy_rts(model, x0, P0, z, run: int):
    kf = KalmanFilter(dim_x=model.n, dim_z=model.m)
    kf.x, kf.P, kf.F, kf.H, kf.Q, kf.R = x0[run].copy(), P0[run].copy(), model.A, model.C, model.Q, model.R
    means, covs, _, _ = kf.batch_filter(list(z[run, 1:]))
    xs, Ps, _, _ = kf.rts_smoother(means, covs)
    return means, xs, Ps


@pytest.mark.parametrize("name", FILTERS)
def test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model(name):
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=40, seed=4)
    est = FILTERS[name](model)
    means, spreads, steps = forward(est, x0, P0, u, z)
    form = est.smoothing_form()
    smoothed, smoothed_spreads = rts_backward(means, spreads[-1], steps, form)
    covs = covariance_of(smoothed_spreads, form.square_root)
    for run in range(2):
        filtered, xs, Ps = filterpy_rts(model, x0, P0, z, run)
        np.testing.assert_allclose(np.array(means)[:, run], filtered, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(smoothed[:, run], xs, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(covs[:, run], Ps, rtol=1e-9, atol=1e-9)
    if form.square_root:  # the square-root smoother keeps lower-triangular factors
        assert np.allclose(np.triu(smoothed_spreads, 1), 0.0)


@pytest.mark.parametrize("baseline", [False, True], ids=["family", "filterpy-ukf"])
@pytest.mark.parametrize("alpha", [1.0, 0.5])
def test_the_unscented_smoother_is_filterpys_on_a_nonlinear_model(alpha, baseline):
    """The same filtered sequence through both smoothers; filterpy's points are made from the
    rows of ``Lᵀ`` (``sqrt_method``), which are the columns of our lower factor ``L``. Both the
    family's UKF and the filterpy baseline (``ukf``, whose steps come from filterpy's own points)."""
    model = smooth_model(seed=3, n=3, m=2, batch_size=1)
    rng = np.random.default_rng(9)
    K = 30
    u = 0.1 * rng.standard_normal((1, K + 1, model.nu))
    z = rng.standard_normal((1, K + 1, model.m))
    x0, P0 = 0.3 * np.ones((1, 3)), np.diag([0.5, 0.3, 0.2])[None]
    est = (
        BatchedFilterpyUKF(model, alpha, 2.0, 0.0)
        if baseline
        else SigmaPointKalmanFilter(model, UnscentedRule(alpha, 2.0, 0.0))
    )
    means, covs, steps = forward(est, x0, P0, u, z)
    smoothed, smoothed_covs = rts_backward(means, covs[-1], steps, est.smoothing_form())

    points = MerweScaledSigmaPoints(3, alpha=alpha, beta=2.0, kappa=0.0, sqrt_method=lambda A: np.linalg.cholesky(A).T)
    step = {"k": 0}

    def fx(x, dt):  # f with the input of the transition filterpy is smoothing across
        return model.f(x[None, None, :], u[:, step["k"] + 1])[0, 0]

    ukf = UnscentedKalmanFilter(dim_x=3, dim_z=2, dt=model.dt, hx=None, fx=fx, points=points)
    ukf.Q = model.Q
    xs, Ps = np.array(means)[:, 0].copy(), np.array(covs)[:, 0].copy()
    for k in reversed(range(K - 1)):  # one transition at a time, with its own input
        step["k"] = k
        x_pair, P_pair, _ = ukf.rts_smoother(xs[k : k + 2].copy(), Ps[k : k + 2].copy())
        xs[k], Ps[k] = x_pair[0], P_pair[0]
    np.testing.assert_allclose(smoothed[:, 0], xs, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(smoothed_covs[:, 0], Ps, rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("name", ["mekf", "sqrt-ut", "cov-cubature"])
def test_fixed_lag_is_the_fixed_interval_on_the_data_up_to_k_plus_lag(name):
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=25, seed=6)
    est = FILTERS[name](model)
    means, spreads, steps = forward(est, x0, P0, u, z)
    form = est.smoothing_form()
    K, lag = len(means), 4
    lagged, lagged_spreads = fixed_lag(means, spreads, steps, form, lag)
    for k in range(K):
        end = min(k + lag, K - 1)
        prefix, prefix_spreads = rts_backward(means[: end + 1], spreads[end], steps[:end], form)
        np.testing.assert_allclose(lagged[k], prefix[k], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(lagged_spreads[k], prefix_spreads[k], rtol=1e-12, atol=1e-12)
    filtered, filtered_spreads = fixed_lag(means, spreads, steps, form, 0)
    np.testing.assert_array_equal(filtered, np.array(means))
    np.testing.assert_array_equal(filtered_spreads, np.array(spreads))
    with pytest.raises(ValueError, match="lag must be an integer >= 0"):
        fixed_lag(means, spreads, steps, form, -1)


def test_smoothing_shrinks_the_covariance_and_on_average_the_error():
    """``P_{k|K} ≤ P_{k|k}`` exactly (eigenvalues of the difference ≥ −round-off); the squared error,
    averaged over 400 runs and all steps, is smaller smoothed than filtered by more than three
    standard errors of the paired difference."""
    runs = 400
    model, _, P0, _, _ = linear_gaussian_problem(runs=runs, steps=1, seed=12)
    rng = np.random.default_rng(13)
    start = rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0[0]).T  # x(0) ~ N(0, P0)
    truth, u, z = simulate(model, start, 40, seed=14)
    est = FILTERS["cov-cubature"](model)
    means, covs, steps = forward(est, np.zeros((runs, 4)), P0, u, z)
    smoothed, smoothed_covs = rts_backward(means, covs[-1], steps, est.smoothing_form())
    assert np.linalg.eigvalsh(np.array(covs) - smoothed_covs).min() > -1e-12
    truth = truth[:, 1:].swapaxes(0, 1)
    filtered_sq = np.sum((np.array(means) - truth) ** 2, axis=-1).mean(axis=0)
    smoothed_sq = np.sum((smoothed - truth) ** 2, axis=-1).mean(axis=0)
    difference = filtered_sq - smoothed_sq
    assert difference.mean() > 3.0 * difference.std(ddof=1) / np.sqrt(runs)


def particle_smoother(est, model, x0, P0, u, z, trajectories: int):
    """FFBSi means and covariances over the steps k = 1..K, and the filter's last weighted mean."""
    est.smoothing = True
    est.set_generators([np.random.default_rng(s) for s in range(len(x0))])
    est.initialize(x0, P0)
    clouds = []
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        clouds.append(est.smoother_cloud)
    means, covs = ffbsi(clouds, model, [np.random.default_rng(10 + s) for s in range(len(x0))], trajectories)
    last = clouds[-1]
    return means, covs, np.einsum("bn,bni->bi", last.weights, last.particles)


def scalar_observed_linear_problem(runs: int, steps: int, seed: int):
    """A 2-state linear-Gaussian model observed in its first state, with process noise large
    enough for a bootstrap filter to track it (a tiny Q, as in :func:`linear_gaussian_problem`,
    starves a bootstrap filter of diversity in the unobserved states): model, x0, P0, u, z."""
    A, C = np.array([[0.9, 0.2], [0.0, 0.8]]), np.array([[1.0, 0.0]])
    Q, R, P0 = np.array([[0.5, 0.1], [0.1, 0.3]]), np.array([[0.4]]), np.array([[1.0, 0.2], [0.2, 0.6]])
    model = LinearGaussianModel(A, C, Q, R, dt=1.0, batch_size=runs)
    start = np.random.default_rng(seed).multivariate_normal(np.zeros(2), P0, runs)
    _, u, z = simulate(model, start, steps, seed)
    return model, np.zeros((runs, 2)), np.repeat(P0[None], runs, axis=0), u, z


@pytest.mark.parametrize("cls", [BootstrapPF, EKPF, UPF])
@pytest.mark.parametrize("particles,trajectories", [(200, 60), (1000, 300)])
@pytest.mark.slow
def test_ffbsi_converges_to_the_rts_smoother_as_particles_grow(cls, particles, trajectories):
    """Each smoothed mean's error, in units of the RTS smoother's standard deviation over √M,
    has a root mean square near 1 (measured 1.2–1.3 for the bootstrap filter: the forward clouds
    add their own error) at every size: the error falls like 1/√M. Ignoring the transition density
    in the backward weights gives the filter's marginals instead, an RMS near 8 here."""
    model, x0, P0, u, z = scalar_observed_linear_problem(runs=2, steps=20, seed=1)
    means, covs = particle_smoother(cls(model, particles=particles), model, x0, P0, u, z, trajectories)[:2]
    for run in range(2):
        _, xs, Ps = filterpy_rts(model, x0, P0, z, run)
        sd = np.sqrt(np.diagonal(Ps, axis1=-2, axis2=-1) / trajectories)
        assert np.sqrt(np.mean(((means[:, run] - xs) / sd) ** 2)) < 1.6
        # sample covariance of M draws: sd of entry ij is √((P_ii P_jj + P_ij²)/M)
        d = np.sqrt(np.diagonal(Ps, axis1=-2, axis2=-1))
        cov_sd = np.sqrt((d[..., :, None] ** 2 * d[..., None, :] ** 2 + Ps**2) / trajectories)
        assert np.sqrt(np.mean(((covs[:, run] - Ps) / cov_sd) ** 2)) < 2.0


def test_ffbsi_refuses_a_bad_trajectory_count():
    model = scalar_observed_linear_problem(runs=1, steps=2, seed=1)[0]
    with pytest.raises(ValueError, match="trajectories must be an integer >= 1"):
        ffbsi([], model, [np.random.default_rng(0)], 0)


@pytest.mark.parametrize("cls", [BootstrapPF, EKPF, UPF, ILOPF])
def test_ffbsi_ends_on_the_filters_last_cloud_for_every_particle_filter(cls):
    """The backward draws start from the last weighted cloud, so the last smoothed mean is the
    filter's weighted mean within four standard errors of M draws. (ILOPF is here and not in the
    convergence test: its particle combination moves its own filter about 1.7 standard deviations
    from the Kalman filter on this model, so its smoother has no RTS smoother to converge to.)"""
    model, x0, P0, u, z = scalar_observed_linear_problem(runs=2, steps=10, seed=3)
    trajectories = 400
    means, covs, filter_mean = particle_smoother(cls(model, particles=500), model, x0, P0, u, z, trajectories)
    sd = np.sqrt(np.diagonal(covs[-1], axis1=-2, axis2=-1) / trajectories)
    assert np.all(np.abs(means[-1] - filter_mean) < 4.0 * sd)
