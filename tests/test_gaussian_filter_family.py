"""The one Gaussian filter with its integrations (estimators/gaussian_filter.py, integrations.py):
identities that hold exactly, whatever the numbers.

- On a linear-Gaussian model every linearisation is exact: the IEKF with any number of
  iterations and the IPLF with any rule and any number of iterations are the Kalman filter
  (the conformance kit, partially observed states and correlated covariances; the unscented
  rule also at α = 1e-3), and the iterated smoothers are the RTS smoother.
- One iteration is the plain filter: the IEKF with 1 iteration is the batched EKF (``mekf`` on a
  vector state), the IPLF with 1 iteration is the sigma-point filter of its rule.
- A measurement's ``residual`` is what the update conditions on: a bearing near ±π is wrapped.
"""

from __future__ import annotations

import numpy as np
import pytest

from quadest.conformance import check_estimator, linear_gaussian_problem
from quadest.errors import ConfigError
from quadest.estimators.error_state_ekf import ErrorStateEKF
from quadest.estimators.gaussian_filter import GaussianFilter
from quadest.estimators.integrations import Integration, StatisticalLinearRegression, Taylor
from quadest.estimators.iterated import IEKF, IPLF, RULES, IPLFParams, integration_rule
from quadest.estimators.params import parameter_problem
from quadest.estimators.registry import builtin_estimators
from quadest.estimators.sigma_point import SigmaPointKalmanFilter
from quadest.estimators.smoother_settings import smoother_settings
from quadest.estimators.smoothing import rts_backward
from quadest.models.base import FilterModel
from quadest.models.book_pendulum import BookPendulumModel

EPS = np.finfo(float).eps

RULE_PARAMS = [
    {"rule": "gauss_hermite", "p": 3},
    {"rule": "unscented", "alpha": 1.0, "beta": 0.0, "kappa": 1.0},
    {"rule": "unscented", "alpha": 1e-3, "beta": 2.0, "kappa": 0.0},
    {"rule": "cubature"},
    {"rule": "cubature5"},
    {"rule": "central_difference"},
]


def _run(est, x0, P0, u, z, smoothing=False):
    est.smoothing = smoothing
    est.initialize(x0.copy(), P0.copy())
    means, covs, steps = [est.mean.copy()], [est.covariance.copy()], []
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        if smoothing:
            steps.append(est.smoother_step)
        est.update(z[:, k], u[:, k])
        means.append(est.mean.copy())
        covs.append(est.covariance.copy())
    return np.array(means), np.array(covs), steps


def _relative(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_iekf_and_iplf_are_registered_as_estimators():
    specs = builtin_estimators()
    assert specs["iekf"].cls is IEKF and specs["iplf"].cls is IPLF


@pytest.mark.parametrize("iterations", [1, 3])
def test_iekf_is_the_kalman_filter_on_a_linear_model(iterations):
    check_estimator(IEKF, {"iterations": iterations}, bad_params=[{"iterations": 0}, {"tolerance": -1.0}])


@pytest.mark.parametrize("iterations", [1, 4])
@pytest.mark.parametrize("params", RULE_PARAMS, ids=lambda p: "-".join(f"{v}" for v in p.values()))
def test_iplf_is_the_kalman_filter_on_a_linear_model_with_any_rule(params, iterations):
    check_estimator(IPLF, {**params, "iterations": iterations}, bad_params=[{"rule": "simpson"}, {"iterations": 0}])


def test_rule_names_are_the_rules_the_iplf_builds():
    assert {integration_rule(name).name for name in RULES} == {
        "gauss_hermite",
        "unscented",
        "cubature3",
        "cubature5",
        "central_difference",
    }


def _pendulum_problem(runs=3, steps=150, seed=4):
    """Pendulum runs from a swinging start, noisy enough that the linearisations matter."""
    rng = np.random.default_rng(seed)
    model = BookPendulumModel(0.01, 9.81, 0.01, 0.1, runs)
    x = np.empty((runs, steps + 1, 2))
    x[:, 0] = np.array([1.5, 0.0]) + 0.1 * rng.standard_normal((runs, 2))
    LQ = np.linalg.cholesky(model.Q)
    for k in range(1, steps + 1):
        x[:, k] = model.f(x[:, k - 1][:, None], np.zeros((runs, 0)))[:, 0] + rng.standard_normal((runs, 2)) @ LQ.T
    z = np.sin(x[..., :1]) + np.sqrt(0.1) * rng.standard_normal((runs, steps + 1, 1))
    P0 = np.broadcast_to(np.eye(2), (runs, 2, 2)).copy()
    return model, np.zeros((runs, 2)), P0, np.zeros((runs, steps + 1, 0)), z


def test_iekf_with_one_iteration_is_the_batched_ekf():
    """``mekf`` on a vector state is the EKF in Joseph form; ours takes ``P⁻ − K S Kᵀ``: the two
    agree to the round-off of 150 recursions (each step loses a few ε relative)."""
    model, x0, P0, u, z = _pendulum_problem()
    xs, Ps, _ = _run(IEKF(model, iterations=1), x0, P0, u, z)
    xr, Pr, _ = _run(ErrorStateEKF(model), x0, P0, u, z)
    assert _relative(xs, xr) < 150 * 1e3 * EPS
    assert _relative(Ps, Pr) < 150 * 1e3 * EPS


@pytest.mark.parametrize("params", RULE_PARAMS[:5], ids=lambda p: p["rule"] + str(p.get("alpha", "")))
def test_iplf_with_one_iteration_is_the_sigma_point_filter_of_its_rule(params):
    """Statistical linear regression then the Kalman update is the sigma-point filter: the same
    moments through ``A = Cᵀ P⁻¹`` and back, to round-off. A weighted sum of points loses about
    ``ε Σ|w_i|`` (``Σ|w_i|`` ≈ 2/α² for the UT at small α), and 150 recursions add up; 100 such
    losses per step is the budget (central differences excluded: their covariance is not a
    weighted sum of outer products, so their filter is not an SLR)."""
    model, x0, P0, u, z = _pendulum_problem()
    rule = integration_rule(**params)
    budget = 150 * 100 * EPS * np.abs(rule.weights(model.n)[1]).sum()
    xs, Ps, _ = _run(IPLF(model, **params, iterations=1), x0, P0, u, z)
    xr, Pr, _ = _run(SigmaPointKalmanFilter(model, rule), x0, P0, u, z)
    assert _relative(xs, xr) < budget
    assert _relative(Ps, Pr) < budget


def test_more_iterations_change_a_nonlinear_update():
    """Guards the loop itself: on the pendulum the 10-iteration filters differ from one iteration."""
    model, x0, P0, u, z = _pendulum_problem()
    one, _, _ = _run(IEKF(model, iterations=1), x0, P0, u, z)
    ten, _, _ = _run(IEKF(model, iterations=10), x0, P0, u, z)
    assert _relative(one, ten) > 1e-3


def test_tolerance_stops_a_converged_run_without_changing_it():
    """A run whose step fell below a tolerance far under the filter's accuracy ends where the full
    iteration count ends, to that tolerance."""
    model, x0, P0, u, z = _pendulum_problem()
    full, _, _ = _run(IEKF(model, iterations=30), x0, P0, u, z)
    early, _, _ = _run(IEKF(model, iterations=30, tolerance=1e-13), x0, P0, u, z)
    assert np.abs(full - early).max() < 1e-11


@pytest.mark.parametrize("est", ["iekf", "iplf"])
def test_iterated_smoothers_are_the_rts_smoother_on_a_linear_model(est):
    """On a linear-Gaussian model every re-linearisation gives the same affine model, so the
    iterated smoother (any number of iterations) is the RTS smoother of the Kalman filter."""
    model, x0, P0, u, z = linear_gaussian_problem(steps=40)
    make = {"iekf": lambda: IEKF(model, iterations=2), "iplf": lambda: IPLF(model, iterations=2)}[est]
    filt = make()
    means, covs, steps = _run(filt, x0, P0, u, z, smoothing=True)
    reference_m, reference_P = rts_backward(list(means), covs[-1], steps, filt.smoothing_form())
    smoothed_m, smoothed_P = filt.iterated_smoothing(3, means, covs)
    assert _relative(smoothed_m[1:], reference_m[1:]) < 1e-10
    assert _relative(smoothed_P[1:], reference_P[1:]) < 1e-10


class _Bearing(FilterModel):
    """A static 2-D position seen from the origin: ``h = atan2(y, x)``, the residual wrapped."""

    name, n, m, nu, dt = "bearing", 2, 1, 0, 1.0
    state_names, state_units, measurement_names = ("x", "y"), ("m", "m"), ("bearing",)

    def __init__(self, wrap: bool) -> None:
        self.Q, self.R, self.wrap = 1e-6 * np.eye(2), np.array([[0.01**2]]), wrap

    def f(self, x, u):
        return x

    def h(self, x, u):
        return np.arctan2(x[..., 1:2], x[..., 0:1])

    def measurement_residual(self, z, predicted):
        d = z - predicted
        return (d + np.pi) % (2 * np.pi) - np.pi if self.wrap else d


@pytest.mark.parametrize("make", [lambda m: IEKF(m, iterations=3), lambda m: IPLF(m, rule="cubature", iterations=3)])
def test_a_wrapped_bearing_residual_is_honoured_near_pi(make):
    """The prior's bearing is −π + 0.01, the measurement π − 0.01: 0.02 rad apart across the cut.
    The prior bearing's variance is ~P/r² = 1e-2 rad², R = 1e-4 rad², so the posterior bearing
    must land within ~0.02 R/(R + 1e-2) ≈ 2e-4 rad of the measurement; we allow 1e-3. Without the
    wrap the update chases a 2π jump (Taylor) or averages points at +π and −π (the SLR's sigma
    points straddle the cut): the posterior bearing is then off by more than 5e-3."""
    x0 = np.array([[-10.0, -0.1]])
    P0 = np.diag([1.0, 1.0])[None]
    z = np.array([[np.pi - 0.01]])
    error = {}
    for wrap in (True, False):
        est = make(_Bearing(wrap))
        est.initialize(x0.copy(), P0.copy())
        est.update(z, np.zeros((1, 0)))
        bearing = np.arctan2(est.mean[0, 1], est.mean[0, 0])
        error[wrap] = abs((bearing - z[0, 0] + np.pi) % (2 * np.pi) - np.pi)
        if wrap:  # the innovation against the prior is the wrapped 0.02 rad, not 2π − 0.02
            assert abs(est.innovation()[0][0, 0]) < 0.021
    assert error[True] < 1e-3
    assert error[False] > 5e-3


def test_a_failed_factorisation_flags_its_run_only():
    """A run whose covariance stops being positive definite is flagged and parked; the others go on."""
    model, x0, P0, u, z = _pendulum_problem(runs=3, steps=5)
    P0 = P0.copy()
    P0[1] = -np.eye(2)
    est = IPLF(model, rule="cubature", iterations=2)
    est.initialize(x0, P0)
    est.predict(u[:, 0])
    est.update(z[:, 1], u[:, 1])
    assert est.failed.tolist() == [False, True, False]
    assert np.isfinite(est.mean).all() and np.isfinite(est.covariance).all()


def test_gaussian_filter_takes_any_integration():
    """The filter is one: the integration object is all that differs between the family's members."""
    model, x0, P0, u, z = _pendulum_problem(runs=1, steps=20)
    a, _, _ = _run(GaussianFilter(model, Integration(Taylor(), 2)), x0, P0, u, z)
    b, _, _ = _run(IEKF(model, iterations=2), x0, P0, u, z)
    c, _, _ = _run(
        GaussianFilter(model, Integration(StatisticalLinearRegression(integration_rule("cubature")))), x0, P0, u, z
    )
    assert np.array_equal(a, b) and not np.allclose(a, c)


def test_a_gauss_hermite_grid_too_large_for_the_model_is_refused_before_any_work():
    """``model=ins`` (15 error states) with Gauss–Hermite at 3 points per dimension would need
    3^15 points: the pre-run check names the key; the default cubature rule passes."""
    problem = parameter_problem(IPLFParams, {"rule": "gauss_hermite"}, 15)
    assert problem is not None and problem[0] == "p" and "3^15" in problem[2]
    assert parameter_problem(IPLFParams, {}, 15) is None  # the default rule, cubature, runs on every model
    assert parameter_problem(IPLFParams, {"rule": "gauss_hermite"}, 2) is None


def test_the_iterated_smoother_is_refused_where_the_filter_cannot_give_it():
    """``smoother: iterated`` needs a filter that re-linearises the whole run (``iekf``, ``iplf``):
    a one-line error naming the key for the others, and for a count that is not >= 1."""
    specs = builtin_estimators()
    settings = smoother_settings("mine", {"smoother": "iterated", "smoother_iterations": 3}, specs["iplf"].cls)
    assert (settings.kind, settings.iterations, settings.label_suffix) == ("iterated", 3, "+smoothed")
    with pytest.raises(ConfigError, match=r"^estimator\.mine\.smoother='iterated' is invalid"):
        smoother_settings("mine", {"smoother": "iterated"}, specs["ckf"].cls)
    with pytest.raises(ConfigError, match=r"^estimator\.mine\.smoother_iterations=0 is invalid"):
        smoother_settings("mine", {"smoother": "iterated", "smoother_iterations": 0}, specs["iekf"].cls)
