"""Particle filters: convergence to the Kalman filter as N grows, the EKF-proposal identity,
batch = alone, same seed same numbers, vanished weights flagged, bad options refused."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import multivariate_normal

from quadest.conformance import linear_gaussian_problem
from quadest.errors import ConfigError
from quadest.estimators.particle import BootstrapPF, weighted_moments
from quadest.estimators.particle_ekpf import EKPF
from quadest.estimators.particle_ilopf import ILOPF
from quadest.estimators.particle_upf import UPF
from quadest.models.functional import LinearGaussianModel

FILTERS = [BootstrapPF, EKPF, ILOPF, UPF]


def _generators(seeds) -> list[np.random.Generator]:
    return [np.random.default_rng(np.random.SeedSequence(int(s))) for s in seeds]


def _run(est, x0, P0, u, z, seeds, before_update=None):
    """Means (K, B, n), covariances (K, B, n, n) and the estimator after the last step."""
    est.set_generators(_generators(seeds))
    est.initialize(x0.copy(), P0.copy())
    means, covs = [], []
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        if before_update is not None:
            before_update(est, k)
        est.update(z[:, k], u[:, k])
        means.append(est.mean.copy())
        covs.append(est.covariance.copy())
    return np.array(means), np.array(covs), est


def _replicated_problem(replicates: int, steps: int = 15, seed: int = 5):
    """One 2-D linear-Gaussian trajectory, repeated over ``replicates`` runs of a batch: the runs
    differ only in their generators, so they are independent particle estimates of one Kalman
    posterior. Q is not small against P0, so every proposal here is a reasonable one."""
    rng = np.random.default_rng(seed)
    A = np.array([[0.9, 0.3], [-0.2, 0.8]])
    C = np.array([[1.0, 0.5]])
    Q = np.array([[0.5, 0.1], [0.1, 0.3]])
    R = np.array([[0.4]])
    P0 = np.array([[1.0, 0.2], [0.2, 0.6]])
    x = rng.multivariate_normal(np.zeros(2), P0)
    z = [np.zeros(1)]
    for _ in range(steps):
        x = A @ x + rng.multivariate_normal(np.zeros(2), Q)
        z.append(C @ x + rng.multivariate_normal(np.zeros(1), R))
    model = LinearGaussianModel(A, C, Q, R, batch_size=replicates)
    zs = np.broadcast_to(np.array(z), (replicates, steps + 1, 1)).copy()
    x0 = np.zeros((replicates, 2))
    return model, x0, np.broadcast_to(P0, (replicates, 2, 2)).copy(), np.zeros((replicates, steps + 1, 0)), zs


def _kalman(model, x0, P0, z):
    kf = KalmanFilter(dim_x=model.n, dim_z=model.m)
    kf.F, kf.H, kf.Q, kf.R, kf.x, kf.P = model.A, model.C, model.Q, model.R, x0.copy(), P0.copy()
    xs, Ps = [], []
    for k in range(1, z.shape[0]):
        kf.predict()
        kf.update(z[k])
        xs.append(kf.x.copy())
        Ps.append(kf.P.copy())
    return np.array(xs), np.array(Ps)


def _normalised_errors(cls, N: int, replicates: int, **options):
    """RMS over replicates and steps of the mean error whitened by the Kalman covariance, and of
    the covariance error relative to the Kalman covariance (Frobenius norm of P_KF^-1/2 ΔP P_KF^-1/2)."""
    model, x0, P0, u, z = _replicated_problem(replicates)
    means, covs, _ = _run(cls(model, particles=N, **options), x0, P0, u, z, seeds=range(replicates))
    xr, Pr = _kalman(model, x0[0], P0[0], z[0])
    Li = np.linalg.inv(np.linalg.cholesky(Pr))  # (K, n, n)
    e_mean = np.einsum("kij,kbj->kbi", Li, means - xr[:, None])
    e_cov = Li[:, None] @ (covs - Pr[:, None]) @ np.swapaxes(Li, -1, -2)[:, None]
    return np.sqrt(np.mean(np.sum(e_mean**2, -1))), np.sqrt(np.mean(np.sum(e_cov**2, (-2, -1))))


@pytest.mark.parametrize("cls", [BootstrapPF, EKPF, UPF])
@pytest.mark.slow
def test_mean_and_covariance_approach_the_kalman_filter_like_one_over_root_n(cls):
    """A consistent particle filter's error obeys a CLT: RMS error ≈ c/√N with c the asymptotic
    standard deviation (in units of the posterior's). We measure c at N1 = 100 and check the
    error at N2 = 16·N1 against c/√N2, with a factor 1.5 for the Monte Carlo spread of the two
    RMS estimates: each averages R·K = 40·15 squared errors (over 2 and 4 components), correlated
    over time, so its relative standard deviation is below ~15 %, and 1.5 is beyond 3 of them.
    A biased filter (an error floor b) fails: b ≈ c/√N1 at N1 would give 4× the bound at N2.
    The absolute bound at N1 is c ≤ 3: the plain Monte Carlo mean of N i.i.d. posterior draws has
    c = 1 and resampling every step on a 15-step problem multiplies the variance by a few
    (Chopin 2004, Thm 2: the asymptotic variance adds one term per resampling)."""
    N1, N2, R = 100, 1600, 40
    m1, c1 = _normalised_errors(cls, N1, R)
    m2, c2 = _normalised_errors(cls, N2, R)
    assert m1 * np.sqrt(N1) <= 3.0 * np.sqrt(2) and c1 * np.sqrt(N1) <= 3.0 * 2, (m1, c1)
    assert m2 <= 1.5 * m1 * np.sqrt(N1 / N2), (m1, m2)
    assert c2 <= 1.5 * c1 * np.sqrt(N1 / N2), (c1, c2)


def test_ekf_proposal_is_the_optimal_proposal_on_a_linear_gaussian_model():
    """With P_i = 0 before the step, N(μ_i, P̂_i) is p(x_k | x_{k−1}^i, y_k), so each particle's
    incremental weight is N(y_k; H F x_{k−1}^i, H Q Hᵀ + R) exactly, whatever x_k^i was drawn."""
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=6, seed=3)
    checked = []

    def reset(est, k):
        est.particle_state["P"][:] = 0.0
        checked.append((k, est.x.copy()))

    est = EKPF(model, particles=50)
    est.set_generators(_generators([0, 1]))
    est.initialize(x0.copy(), P0.copy())
    S = model.C @ model.Q @ model.C.T + model.R
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        reset(est, k)
        x_prev = checked[-1][1]
        est.update(z[:, k], u[:, k])
        for b in range(2):
            expected = multivariate_normal(cov=S).logpdf(z[b, k] - x_prev[b] @ (model.C @ model.A).T)
            np.testing.assert_allclose(est.log_increment[b], expected, rtol=1e-10, atol=1e-10)
    assert len(checked) == z.shape[1] - 1


@pytest.mark.parametrize("augmented", [True, False])
def test_ukf_proposal_equals_the_ekf_proposal_on_a_linear_gaussian_model(augmented):
    """The UT is exact for linear functions, so on a linear-Gaussian model the UKF step from every
    (x_i, P_i) gives the EKF step's (μ_i, P̂_i) to round-off, whatever α, β, κ."""
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=2, seed=8)
    clouds = []
    for cls, extra in ((EKPF, {}), (UPF, {"augmented": augmented, "alpha": 0.7, "kappa": 1.0})):
        est = cls(model, particles=20, proposal_Q=0.3, proposal_R=0.2, **extra)
        est.set_generators(_generators([0, 1]))
        est.initialize(x0, P0)
        est.particle_state["P"] *= 1.0 + np.arange(20.0)[None, :, None, None]  # a different P_i per particle
        clouds.append(est.proposal_moments(u[:, 0], z[:, 1], u[:, 1]))
    (mu_e, P_e), (mu_u, P_u) = clouds
    np.testing.assert_allclose(mu_u, mu_e, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(P_u, P_e, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("cls", FILTERS)
@pytest.mark.parametrize("options", [{}, {"schedule": "ess", "estimate": "resampled", "roughening": 0.2}])
def test_batch_equals_alone_and_same_seed_same_numbers(cls, options):
    model, x0, P0, u, z = linear_gaussian_problem(runs=3, steps=10)
    seeds = [11, 12, 13]
    means, covs, est = _run(cls(model, particles=64, **options), x0, P0, u, z, seeds)
    assert not est.failed.any()
    for i in range(3):
        alone = cls(model.select(i), particles=64, **options)
        mi, ci, _ = _run(alone, *(a[i : i + 1] for a in (x0, P0, u, z)), [seeds[i]])
        np.testing.assert_array_equal(means[:, i], mi[:, 0])
        np.testing.assert_array_equal(covs[:, i], ci[:, 0])
    again, _, _ = _run(cls(model, particles=64, **options), x0, P0, u, z, seeds)
    np.testing.assert_array_equal(again, means)


@pytest.mark.parametrize("cls", FILTERS)
def test_a_run_whose_weights_all_vanish_is_flagged_and_the_others_carry_on(cls):
    """A measurement so far away that every likelihood underflows to zero (log N = −∞)."""
    model, x0, P0, u, z = linear_gaussian_problem(runs=3, steps=8)
    bad = z.copy()
    bad[1, 4] = 1e200
    means, _, est = _run(cls(model, particles=32), x0, P0, u, bad, [1, 2, 3])
    assert est.failed.tolist() == [False, True, False]
    assert "weights vanished at step 4" in est.failure_reasons[1]
    assert np.isfinite(means).all()
    ref, _, _ = _run(cls(model, particles=32), x0, P0, u, z, [1, 2, 3])
    np.testing.assert_array_equal(means[:, [0, 2]], ref[:, [0, 2]])


def test_ess_schedule_resamples_only_below_the_threshold_and_counts():
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=10)
    est = BootstrapPF(model, particles=100, schedule="ess", ess_threshold=0.3)
    est.set_generators(_generators([0, 1]))
    est.initialize(x0, P0)
    total = np.zeros(2, dtype=int)
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        resampled = est.ess < 0.3 * 100
        total += resampled
        assert np.allclose(np.exp(est.logw[resampled]), 1 / 100)
    np.testing.assert_array_equal(est.resample_count, total)
    assert 0 < total.sum() < 2 * 10


@pytest.mark.parametrize(
    ("cls", "bad"),
    [
        (BootstrapPF, {"particles": 1}),
        (BootstrapPF, {"resampling": "roulette"}),
        (BootstrapPF, {"schedule": "sometimes"}),
        (BootstrapPF, {"ess_threshold": 0.0}),
        (BootstrapPF, {"estimate": "median"}),
        (BootstrapPF, {"roughening": -1.0}),
        (BootstrapPF, {"initial_cloud": "grid"}),
        (BootstrapPF, {"initial_range": [1.0, 0.0]}),
        (BootstrapPF, {"initial_range": [0.0]}),
        (BootstrapPF, {"weights": "linear"}),
        (BootstrapPF, {"weight_floor": 0.0}),
        (BootstrapPF, {"vanished_weights": "drop"}),
        (EKPF, {"proposal_Q": 0.0}),
        (ILOPF, {"coefficient": "gamma"}),
        (ILOPF, {"threshold": 0.0}),
        (UPF, {"alpha": 0.0}),
    ],
)
def test_bad_options_are_one_line_config_errors(cls, bad):
    model = linear_gaussian_problem(runs=1, steps=1)[0]
    with pytest.raises(ConfigError, match=next(iter(bad))):
        cls(model, **bad)


@pytest.mark.parametrize(
    ("kind", "bad"),
    [
        ("pf", {"weights": "linear"}),
        ("ekpf", {"vanished_weights": "drop"}),
        ("upf", {"resampling": "roulette"}),
        ("ilopf", {"initial_cloud": "grid"}),
        ("ilopf", {"coefficient": "gamma"}),
        ("pf", {"initial_range": [2.0, 2.0]}),
        ("ekpf", {"weight_floor": -1.0}),
    ],
)
def test_bad_choices_are_caught_by_the_pre_run_validation(kind, bad):
    """The same options as the constructor refuses, found from the ``Params`` alone (what
    ``quadest`` checks before any work)."""
    from quadest.estimators.params import parameter_problem
    from quadest.estimators.registry import builtin_estimators

    key, value = next(iter(bad.items()))
    problem = parameter_problem(builtin_estimators()[kind].params, bad, 3)
    assert problem is not None and problem[:2] == (key, value)


def test_initialize_without_generators_says_what_is_missing():
    model, x0, P0, _, _ = linear_gaussian_problem(runs=2, steps=1)
    with pytest.raises(RuntimeError, match="set_generators"):
        BootstrapPF(model).initialize(x0, P0)


def test_weighted_moments_by_hand_leaving_out_zero_weight_particles_even_non_finite_ones():
    """Mean and covariance computed by hand: run 0 has a NaN particle of weight 0, which must not
    poison its run; a batch of positive weights only takes the path without masking."""
    x = np.array([[[1.0], [3.0], [np.nan]], [[0.0], [2.0], [4.0]]])
    w = np.array([[0.5, 0.5, 0.0], [0.25, 0.5, 0.25]])
    mean, cov = weighted_moments(x, w)
    np.testing.assert_array_equal(mean, [[2.0], [2.0]])  # (1 + 3)/2; 0.5·2 + 0.25·4
    np.testing.assert_array_equal(cov, [[[1.0]], [[2.0]]])  # 0.5·1 + 0.5·1; 0.25·4 + 0.25·4
    mean, cov = weighted_moments(x[1:], w[1:])
    np.testing.assert_array_equal(mean, [[2.0]])
    np.testing.assert_array_equal(cov, [[[2.0]]])


def test_resampling_carries_each_particles_covariance_with_it():
    model, x0, P0, _, _ = linear_gaussian_problem(runs=2, steps=1)
    est = EKPF(model, particles=6)
    est.set_generators(_generators([4, 5]))
    est.initialize(x0, P0)
    est.x[:] = np.arange(6.0)[None, :, None]  # particle i sits at i in every coordinate ...
    est.particle_state["P"][:] = np.arange(6.0)[None, :, None, None] * np.eye(4)  # ... with P_i = i I
    w = np.array([[0.0, 0.5, 0.0, 0.3, 0.2, 0.0], [0.1, 0.1, 0.1, 0.1, 0.1, 0.5]])
    est.resample_runs(w, np.arange(2))
    ancestor = est.x[..., 0]
    np.testing.assert_array_equal(est.particle_state["P"], ancestor[..., None, None] * np.eye(4))
    assert set(np.unique(ancestor[0])) <= {1.0, 3.0, 4.0}


def test_upf_benchmark_noise_density_jacobians_and_switch():
    """The Gamma(3, rate 2) density against scipy, −∞ outside its support, draws with its mean
    (3/2 ± 5 standard errors √(3/4 / M)), analytic Jacobians against central differences, and the
    measurement switch after t = 30."""
    from scipy.stats import gamma

    from quadest.models.upf_benchmark import UPFBenchmarkModel

    model = UPFBenchmarkModel(Q=0.75, R=1e-5, batch_size=2)
    w = np.array([[-0.5], [0.0], [0.3], [1.5], [4.0]])
    expected = gamma(a=3.0, scale=0.5).logpdf(w[:, 0])
    np.testing.assert_allclose(model.process_noise_logpdf(w), expected, rtol=1e-12)
    assert np.isneginf(model.process_noise_logpdf(w)[:2]).all()
    draws = model.sample_process_noise(np.random.default_rng(0), (20000,))
    assert draws.shape == (20000, 1) and abs(draws.mean() - 1.5) < 5 * np.sqrt(0.75 / 20000)
    x = np.array([[[1.3], [2.0]], [[0.7], [3.1]]])
    for t in (30.0, 31.0):
        u = np.full((2, 1), t)
        np.testing.assert_allclose(model.H_points(x, u), model.jacobian_fd_points(model.h, x, u), rtol=1e-8)
        np.testing.assert_allclose(model.F_points(x, u), model.jacobian_fd_points(model.f, x, u), rtol=1e-8)
    np.testing.assert_allclose(model.h(x, np.full((2, 1), 30.0)), 0.2 * x**2)
    np.testing.assert_allclose(model.h(x, np.full((2, 1), 31.0)), 0.5 * x - 2.0)
    np.testing.assert_allclose(model.f(x, np.full((2, 1), 1.0)), 1.0 + np.sin(0.08 * np.pi) + 0.5 * x)


def test_ilopf_combines_a_copy_particle_with_a_discard_particle_by_eq_8():
    """Copy group {w ≥ 1/N} = {0}, discard group {0 < w < 1/N} = {1, 2}; particle 3 has zero
    weight and belongs to neither. With the classic coefficient ρ = (N w_0)^(−1/n) every new
    particle is x_0 + ρ (x_s − x_0) with x_s one of x_1, x_2, and keeps P_0."""
    model, x0, P0, _, _ = linear_gaussian_problem(runs=1, steps=1)
    est = ILOPF(model, particles=4, coefficient="classic")
    est.set_generators(_generators([9]))
    est.initialize(x0, P0)
    est.x[:] = np.array([[0.0, 0, 0, 0], [1, 2, 3, 4], [-1, 0, 1, 0], [9, 9, 9, 9]])[None]
    est.particle_state["P"][:] = (1.0 + np.arange(4.0))[None, :, None, None] * np.eye(4)
    w = np.array([[0.85, 0.1, 0.05, 0.0]])
    est.resample_runs(w, np.arange(1))
    rho = (4 * 0.85) ** (-1 / 4)
    candidates = rho * np.array([[1.0, 2, 3, 4], [-1, 0, 1, 0]])
    for particle in est.x[0]:
        assert np.isclose(candidates, particle, rtol=1e-12, atol=1e-12).all(axis=1).any(), particle
    np.testing.assert_array_equal(est.particle_state["P"][0], np.broadcast_to(np.eye(4), (4, 4, 4)))
    # no discard group (the other weights are all zero): plain resampling of the copy group
    est.x[:] = np.array([[0.0, 0, 0, 0], [1, 2, 3, 4], [-1, 0, 1, 0], [9, 9, 9, 9]])[None]
    est.resample_runs(np.array([[0.6, 0.4, 0.0, 0.0]]), np.arange(1))
    assert np.isin(est.x[0, :, 3], [0.0, 4.0]).all()
    # a threshold above every weight empties the copy group: plain resampling of all particles
    high = ILOPF(model, particles=4, threshold=3.9)
    high.set_generators(_generators([9]))
    high.initialize(x0, P0)
    high.x[:] = np.array([[0.0, 0, 0, 0], [1, 2, 3, 4], [-1, 0, 1, 0], [9, 9, 9, 9]])[None]
    high.resample_runs(np.array([[0.5, 0.3, 0.2, 0.0]]), np.arange(1))
    assert np.isin(high.x[0, :, 3], [0.0, 4.0]).all() and np.isfinite(high.x).all()


def test_upf_benchmark_data_follow_the_model():
    """The truth starts at x0 and moves by Gamma(3, rate 2) increments (all positive, mean 3/2 and
    variance 3/4 within 5 standard errors), the measurements by N(0, R) noise, the input is t."""
    from quadest.config.settings import DataSettings
    from quadest.models.schemas import UPFBenchmarkModelConf
    from quadest.simulation.upf_benchmark_data import build_upf_benchmark_data

    model = UPFBenchmarkModelConf(Q=0.75, R=1e-5, gamma_shape=3.0, gamma_rate=2.0, switch_time=30.0, x0=1.0, P0=0.75)
    data = build_upf_benchmark_data(DataSettings(runs=40, seed=1, duration=59.0, sample_period=1.0, model=model))
    x, u, z, model = data.truth, data.inputs, data.measurements, data.model
    assert (x[:, 0] == 1.0).all() and (u[:, :, 0] == np.arange(1.0, 61.0)).all()
    v = np.stack([x[:, k] - model.f(x[:, k - 1][:, None], u[:, k - 1])[:, 0] for k in range(1, 60)], axis=1)
    M = v.size
    assert (v > 0).all() and abs(v.mean() - 1.5) < 5 * np.sqrt(0.75 / M)
    assert abs(v.var() - 0.75) < 5 * np.sqrt((np.mean((v - 1.5) ** 4) - 0.75**2) / M)
    n = np.stack([z[:, k] - model.h(x[:, k][:, None], u[:, k])[:, 0] for k in range(60)], axis=1)
    assert abs(n.var() / 1e-5 - 1.0) < 5 * np.sqrt(2.0 / n.size)


def test_seed001_rate_model_jacobian_matches_central_differences():
    """The analytic ``I + T ∂ω̇/∂ω`` against central differences of ``f`` (step 1e-6: error ~1e-9)."""
    from quadest.models.seed001_rates import RateModel
    from quadest.quadrotor.params import QuadrotorParams

    rng = np.random.default_rng(4)
    model = RateModel(QuadrotorParams(), 0.02, 0.1 * np.eye(3), 0.1 * np.eye(3), batch_size=2)
    x = rng.normal(scale=2.0, size=(2, 5, 3))
    u = rng.uniform(150.0, 300.0, size=(2, 4))
    np.testing.assert_allclose(model.F_points(x, u), model.jacobian_fd_points(model.f, x, u), rtol=0, atol=1e-8)
    np.testing.assert_allclose(model.F(x[:, 0], u), model.F_points(x, u)[:, 0], rtol=1e-14)


def _recording_proposals(est) -> list:
    """Wrap ``est.propose`` so every proposed cloud (B, N, n) is kept (before weighting and resampling)."""
    proposed, propose = [], est.propose

    def record(*args):
        x_new, log_q = propose(*args)
        proposed.append(x_new.copy())
        return x_new, log_q

    est.propose = record
    return proposed


def test_linear_floor_weights_are_the_likelihood_plus_the_floor_normalised():
    """One bootstrap step without resampling: the weights equal (N(y; C x_i, R) + floor) / Σ, the
    density from scipy, with a floor at the median likelihood so that it matters for half the
    particles (added in the log domain instead, or left out, the weights differ by far more than
    round-off). The proposed cloud does not depend on the weights, so both runs see it."""
    model, x0, P0, u, z = linear_gaussian_problem(runs=1, steps=1)
    options = {"particles": 50, "schedule": "ess", "ess_threshold": 1e-9}  # ESS >= 1 > 50e-9: never resamples
    exact = BootstrapPF(model, **options)
    proposed = _recording_proposals(exact)
    _run(exact, x0, P0, u, z, [7])
    lik = multivariate_normal(mean=np.zeros(2), cov=model.R).pdf(z[0, 1] - proposed[0][0] @ model.C.T)
    floor = float(np.median(lik))
    floored = BootstrapPF(model, weights="linear_floor", weight_floor=floor, **options)
    _run(floored, x0, P0, u, z, [7])
    np.testing.assert_array_equal(floored.x, exact.x)
    expected = (lik + floor) / np.sum(lik + floor)
    np.testing.assert_allclose(np.exp(floored.logw[0]), expected, rtol=1e-12)  # round-off of exp/log
    np.testing.assert_allclose(np.exp(exact.logw[0]), lik / lik.sum(), rtol=1e-12)
    assert floored.floored_steps.tolist() == [0]


def test_when_no_particle_explains_y_the_floor_gives_equal_weights_and_no_correction():
    """A measurement 1e3 away (log-likelihoods around −1e6: finite, but exp underflows to 0): with
    ``linear_floor`` every weight is the floor, the weights are exactly 1/N, the estimate is the
    plain mean of the prior cloud and systematic resampling of equal weights keeps every particle
    once, in order (position (i + U)/N lies in particle i's slice). The exact log-domain filter
    instead puts (almost) all weight on the particle nearest the measurement."""
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=3)
    far = z.copy()
    far[:, 2] += 1e3
    runs = {}
    for weights in ("linear_floor", "log"):
        est = BootstrapPF(model, particles=40, weights=weights, resampling="systematic")
        proposed = _recording_proposals(est)

        def check_step_2(est, k, proposed=proposed, weights=weights):
            if k == 3:
                runs[weights] = (proposed[1], est.x.copy(), est.mean.copy(), est.ess.copy())

        _run(est, x0, P0, u, far, [1, 2], before_update=check_step_2)
        assert est.floored_steps.tolist() == [1, 1]
        assert not est.failed.any()
    cloud, after, mean, ess = runs["linear_floor"]
    np.testing.assert_allclose(ess, [40.0, 40.0], rtol=1e-14)  # 1/Σ(1/40)²: round-off of the sum
    np.testing.assert_array_equal(after, cloud)
    np.testing.assert_allclose(mean, cloud.mean(axis=1), rtol=1e-13, atol=1e-15)  # sum order only
    assert np.all(runs["log"][3] < 2.0)


@pytest.mark.parametrize("cls", FILTERS)
def test_uniform_policy_never_flags_and_carries_on_with_equal_weights(cls):
    """Run 1's weights all vanish at step 4 (its previous log-weights set to −∞ just before the
    update: every product is zero, for any proposal). With ``vanished_weights: uniform`` no run
    fails, the step is counted, run 1 carries on with equal weights and the other runs are
    untouched; with the default the same run is flagged."""
    model, x0, P0, u, z = linear_gaussian_problem(runs=3, steps=8)
    seen = {}

    def zero_weights_at_4(est, k):
        if k == 4:
            est.logw[1] = -np.inf
        if k == 5:
            seen["logw"] = est.logw.copy()

    uniform = cls(model, particles=32, vanished_weights="uniform")
    means, _, est = _run(uniform, x0, P0, u, z, [1, 2, 3], zero_weights_at_4)
    assert not est.failed.any()
    assert est.vanished_steps.tolist() == [0, 1, 0]
    np.testing.assert_array_equal(seen["logw"][1], np.full(32, -np.log(32)))
    assert np.isfinite(means).all()
    ref, _, _ = _run(cls(model, particles=32), x0, P0, u, z, [1, 2, 3])
    np.testing.assert_array_equal(means[:, [0, 2]], ref[:, [0, 2]])
    _, _, flagged = _run(cls(model, particles=32), x0, P0, u, z, [1, 2, 3], zero_weights_at_4)
    assert flagged.failed.tolist() == [False, True, False]


@pytest.mark.parametrize("cls", [BootstrapPF, EKPF, ILOPF, UPF])
def test_the_numerics_options_leave_the_exact_filter_bit_for_bit(cls):
    """The defaults are the exact filter (log-domain weights, vanished runs flagged, the cloud
    drawn from N(x0, P0)): naming those options changes no bit, and the demo's linear-domain
    weights with a floor far below every likelihood (1e-300 against log-likelihoods of order 1:
    ``logaddexp(log p, log floor) = log p + log1p(e^(log floor − log p))`` adds about 1e-290 to
    numbers of order 1, which rounds away) give the same bits too. (When the options were added,
    commit 2fba698 compared SHA-256 digests of every step against the code before them; a digest
    depends on the BLAS kernels of the machine, OPENBLAS_CORETYPE among them, so it is no test.)"""
    model, x0, P0, u, z = linear_gaussian_problem(runs=2, steps=6)
    default = _run(cls(model, particles=16), x0, P0, u, z, [3, 4])
    for options in (
        {"weights": "log", "vanished_weights": "flag", "initial_cloud": "sample"},
        {"weights": "linear_floor", "weight_floor": 1e-300},
    ):
        means, covs, _ = _run(cls(model, particles=16, **options), x0, P0, u, z, [3, 4])
        np.testing.assert_array_equal(means, default[0], err_msg=str(options))
        np.testing.assert_array_equal(covs, default[1], err_msg=str(options))


def test_uniform_initial_cloud_covers_the_range_whatever_x0():
    """``initial_cloud: uniform`` on [−2, 3]: every coordinate inside, with the uniform's mean 0.5
    and variance 25/12 within 5 standard errors (M = 2·4000 draws per coordinate), x0 ignored."""
    model, x0, P0, _, _ = linear_gaussian_problem(runs=2, steps=1)
    est = BootstrapPF(model, particles=4000, initial_cloud="uniform", initial_range=[-2.0, 3.0])
    est.set_generators(_generators([1, 2]))
    est.initialize(x0 + 100.0, P0)
    x = est.x.reshape(-1, 4)
    assert x.min() >= -2.0 and x.max() < 3.0
    M, var = x.shape[0], 25.0 / 12.0
    assert np.all(np.abs(x.mean(axis=0) - 0.5) < 5 * np.sqrt(var / M))
    assert np.all(np.abs(x.var(axis=0) - var) < 5 * np.sqrt((625.0 / 80.0 - var**2) / M))  # Var(U²)-type: μ4 − σ⁴
