"""The SR-UKF is the thesis algorithm: identities it must satisfy to round-off.

- SR-UKF ≡ filterpy 2.0 UKF (both redraw sigma points before the update; filterpy's Cholesky rows
  are the columns of the lower factor), on a random smooth model with correlated non-identity
  P0, Q, R and m < n, and on both quadrotor filter models, over α ∈ {1e-3, 0.5, 1} × β ∈ {0, 2} × κ ∈ {0, 3 − n}.
- On a linear-Gaussian model SR-UKF, filterpy UKF and filterpy EKF equal filterpy's KalmanFilter.
- The batched SR-UKF gives each run what that run gives alone.
- A run whose covariance loses definiteness is flagged; the other runs keep their numbers.
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from helpers import compose_config, random_spd, run_filter, simulate, smooth_model
from quadest.app.settings import data_settings
from quadest.estimators import srukf as srukf_module
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.filterpy_ekf import FilterpyEKF
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.sigma_point import SquareRootSigmaPointFilter
from quadest.estimators.srukf import SRUKF
from quadest.models.functional import FunctionalModel, LinearGaussianModel
from quadest.numerics import ut_weights
from quadest.simulation.quadrotor_data import build_quadrotor_data

GRID = [(a, b, k) for a in (1e-3, 0.5, 1.0) for b in (0.0, 2.0) for k in ("zero", "3-n")]


def roundoff_floor(model, x0, P0, u, z, alpha, beta, kappa) -> tuple[float, float]:
    """How far filterpy's own UKF moves when its initial mean is perturbed by about two ulps:
    the round-off sensitivity of this problem at these parameters, for the means and the
    covariances. It is measured without the SR-UKF, so it is an independent yardstick.

    At α ≥ 0.5 it is ~1e-14. At α = 1e-3 the UT takes second differences of f at a spread of
    about 1e-3 σ, and the sensitivity reaches 1e-9…1e-6 depending on the model: no
    double-precision UKF can agree with another to 1e-9 there.
    """
    x0p = x0 * (1.0 + 4e-16 * np.random.default_rng(0).standard_normal(x0.shape))
    a = run_filter(PerRunAdapter(model, FilterpyUKF, alpha=alpha, beta=beta, kappa=kappa), model, x0, P0, u, z)
    b = run_filter(PerRunAdapter(model, FilterpyUKF, alpha=alpha, beta=beta, kappa=kappa), model, x0p, P0, u, z)
    finite = np.isfinite(a[0]).all(axis=(0, 2)) & np.isfinite(b[0]).all(axis=(0, 2))
    if not finite.any():
        return 0.0, 0.0
    return relative(b[0][:, finite], a[0][:, finite]), relative(b[1][:, finite], a[1][:, finite])


def tolerances(model, x0, P0, u, z, alpha, beta, kappa) -> tuple[float, float]:
    """1e-9 relative, or ten times the measured round-off floor where that is larger. A lost
    sign of W0(c), a dropped W0 term, a transposed factor or an unfactored P0 all give
    differences of order one."""
    fx, fP = roundoff_floor(model, x0, P0, u, z, alpha, beta, kappa)
    return max(1e-9, 10.0 * fx), max(1e-9, 10.0 * fP)


def w_c0_nonnegative(n: int, alpha: float, beta: float, kappa: float) -> bool:
    """With W0(c) ≥ 0 every weight is non-negative and no run may be flagged."""
    return ut_weights(n, alpha, beta, kappa).wc[0] >= 0


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def compare_srukf_filterpy(model, x0, P0, u, z, alpha, beta, kappa):
    """Run both filters; check they flag the same runs (the SR-UKF no later: it sees the
    indefinite covariance in its downdate, filterpy only when it next factors P) and return the
    estimates of both, per run, over the steps before that run was flagged."""
    sr_fail, fp_fail = {}, {}
    sr = run_filter(SRUKF(model, alpha, beta, kappa), model, x0, P0, u, z, sr_fail)
    fp = run_filter(
        PerRunAdapter(model, FilterpyUKF, alpha=alpha, beta=beta, kappa=kappa), model, x0, P0, u, z, fp_fail
    )
    assert sorted(sr_fail) == sorted(fp_fail)
    assert all(sr_fail[i] <= fp_fail[i] for i in sr_fail)
    for i in range(x0.shape[0]):
        alive = sr_fail.get(i, u.shape[1]) - 1
        yield (sr[0][:alive, i], sr[1][:alive, i]), (fp[0][:alive, i], fp[1][:alive, i])


@pytest.mark.parametrize(("alpha", "beta", "kappa"), GRID)
@pytest.mark.parametrize("seed", [0, 1])
def test_srukf_equals_filterpy_ukf_on_random_smooth_model(seed, alpha, beta, kappa):
    n = 4
    kappa = 0.0 if kappa == "zero" else 3.0 - n
    model = smooth_model(seed, n=n, m=2)
    rng = np.random.default_rng(100 + seed)
    P0 = random_spd(rng, n, 0.5)[None]
    x_true, u, z = simulate(model, rng.standard_normal((1, n)), 120, seed)
    x0 = x_true[:, 0] + rng.standard_normal((1, n)) @ np.linalg.cholesky(P0[0]).T
    tol_x, tol_P = tolerances(model, x0, P0, u, z, alpha, beta, kappa)
    if alpha >= 0.5:
        assert tol_x == tol_P == 1e-9
    for (xs, Ps), (xf, Pf) in compare_srukf_filterpy(model, x0, P0, u, z, alpha, beta, kappa):
        assert xs.shape[0] >= 100
        assert relative(xs, xf) <= tol_x
        assert relative(Ps, Pf) <= tol_P


def test_per_point_and_vectorised_filterpy_calls_agree():
    """Evaluating filterpy's sigma points in one call does not change its numbers."""
    model = smooth_model(3)
    rng = np.random.default_rng(3)
    P0 = random_spd(rng, 4, 0.5)[None]
    _, u, z = simulate(model, np.zeros((1, 4)), 50, 3)
    a = run_filter(
        PerRunAdapter(model, FilterpyUKF, alpha=0.5, vectorize_points=False), model, np.zeros((1, 4)), P0, u, z
    )
    b = run_filter(
        PerRunAdapter(model, FilterpyUKF, alpha=0.5, vectorize_points=True), model, np.zeros((1, 4)), P0, u, z
    )
    np.testing.assert_allclose(a[0], b[0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(a[1], b[1], rtol=0, atol=1e-13)


@pytest.fixture(scope="module", params=["thesis", "augmented"])
def quadrotor_data(request):
    cfg = compose_config(
        [
            f"model.formulation={request.param}",
            "runs=2",
            "duration=1.2",
            "model.initial_std.correlation=0.3",
            "scenario=figure8",
        ]
    )
    return build_quadrotor_data(data_settings(cfg))


def quadrotor_io(data):
    """Inputs with the companion values the thesis model needs, from the truth (so both filters
    see exactly the same inputs)."""
    m = data.model
    K1 = data.time.size
    u = np.stack([m.filter_input(data.inputs[:, k], data.companion_truth[:, k]) for k in range(K1)], axis=1)
    return u, data.measurements


def quadrotor_case(data, alpha: float, beta: float, kappa):
    """``(kappa, u, z, P0, tol_x, tol_P)`` of one grid cell on the quadrotor data (``"zero"`` or
    the 3 − n heuristic for κ)."""
    n = data.model.n
    kappa = 0.0 if kappa == "zero" else 3.0 - n
    u, z = quadrotor_io(data)
    P0 = np.broadcast_to(data.P0, (data.x0.shape[0], n, n))
    return (kappa, u, z, P0, *tolerances(data.model, data.x0, P0, u, z, alpha, beta, kappa))


@pytest.mark.parametrize(("alpha", "beta", "kappa"), GRID)
@pytest.mark.slow
def test_srukf_equals_filterpy_ukf_on_quadrotor(quadrotor_data, alpha, beta, kappa):
    data = quadrotor_data
    n = data.model.n
    kappa, u, z, P0, tol_x, tol_P = quadrotor_case(data, alpha, beta, kappa)
    if alpha >= 0.5:
        assert tol_x == tol_P == 1e-9
    compared = 0
    for (xs, Ps), (xf, Pf) in compare_srukf_filterpy(data.model, data.x0, P0, u, z, alpha, beta, kappa):
        if xs.shape[0] == 0:  # flagged by both at the first step (an indefinite UT covariance)
            continue
        assert relative(xs, xf) <= tol_x
        assert relative(Ps, Pf) <= tol_P
        compared = max(compared, xs.shape[0])
    if w_c0_nonnegative(n, alpha, beta, kappa):
        assert compared >= 100


class FamilySRUKF(SRUKF):
    """The SR-UKF through the sigma-point family's steps only (the reference of the fused path)."""

    predict = SquareRootSigmaPointFilter.predict
    update = SquareRootSigmaPointFilter.update


@pytest.mark.parametrize(("alpha", "beta", "kappa"), GRID)
@pytest.mark.slow
def test_fused_srukf_steps_equal_the_sigma_point_family_on_quadrotor(quadrotor_data, alpha, beta, kappa, monkeypatch):
    """On the compiled backend the plain SR-UKF steps through :mod:`quadest.numerics.unscented`;
    it must give the family's numbers (the same tolerance as against filterpy) and flag the same
    runs at the same steps."""
    from quadest.numerics import unscented

    calls = []
    moments = unscented.unscented_moments
    monkeypatch.setattr(srukf_module, "unscented_moments", lambda *a: calls.append(1) or moments(*a))
    data = quadrotor_data
    kappa, u, z, P0, tol_x, tol_P = quadrotor_case(data, alpha, beta, kappa)
    fused_fail, family_fail = {}, {}
    fused = run_filter(SRUKF(data.model, alpha, beta, kappa), data.model, data.x0, P0, u, z, fused_fail)
    assert len(calls) == 2 * (u.shape[1] - 1)
    family = run_filter(FamilySRUKF(data.model, alpha, beta, kappa), data.model, data.x0, P0, u, z, family_fail)
    assert len(calls) == 2 * (u.shape[1] - 1)
    assert fused_fail == family_fail
    for i in range(data.x0.shape[0]):
        alive = fused_fail.get(i, u.shape[1]) - 1
        if alive:
            assert relative(fused[0][:alive, i], family[0][:alive, i]) <= tol_x
            assert relative(fused[1][:alive, i], family[1][:alive, i]) <= tol_P


def linear_problem(seed: int = 7):
    """2-D constant velocity, position measured (m = 2 < n = 4), correlated P0, Q, R."""
    dt = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    C = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    rng = np.random.default_rng(seed)
    Q, R, P0 = random_spd(rng, 4, 0.01), random_spd(rng, 2, 0.2), random_spd(rng, 4, 1.0)
    model = LinearGaussianModel(A, C, Q, R, dt=dt)
    x_true, u, z = simulate(model, np.array([[0.0, 0.0, 1.0, -0.5]]), 150, seed)
    x0 = x_true[:, 0] + rng.standard_normal((1, 4)) @ np.linalg.cholesky(P0).T
    return model, x0, P0, u, z


def kalman_reference(model, x0, P0, z):
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.H, kf.Q, kf.R = model.A, model.C, model.Q, model.R
    kf.x, kf.P = x0[0].copy(), P0.copy()
    xs, Ps = [], []
    for k in range(1, z.shape[1]):
        kf.predict()
        kf.update(z[0, k])
        xs.append(kf.x.copy())
        Ps.append(kf.P.copy())
    return np.array(xs), np.array(Ps)


@pytest.mark.parametrize(
    ("name", "make"),
    [
        ("srukf", lambda m: SRUKF(m, 0.5, 2.0, 0.0)),
        ("srukf_alpha1_beta0", lambda m: SRUKF(m, 1.0, 0.0, 0.0)),
        ("ukf", lambda m: PerRunAdapter(m, FilterpyUKF, alpha=0.5)),
        ("ekf", lambda m: PerRunAdapter(m, FilterpyEKF)),
    ],
)
def test_every_gaussian_filter_equals_kalman_filter_on_linear_model(name, make):
    model, x0, P0, u, z = linear_problem()
    xs, Ps = run_filter(make(model), model, x0, P0[None], u, z)
    xr, Pr = kalman_reference(model, x0, P0, z)
    assert relative(xs[:, 0], xr) <= 1e-9
    assert relative(Ps[:, 0], Pr) <= 1e-9


@pytest.mark.parametrize("alpha", [1e-3, 0.5])
def test_batched_srukf_equals_each_run_alone(alpha):
    B, n = 5, 4
    model = smooth_model(11, n=n, batch_size=B)
    rng = np.random.default_rng(11)
    P0 = np.stack([random_spd(rng, n, 0.5) for _ in range(B)])
    x_true, u, z = simulate(model, rng.standard_normal((B, n)), 100, 11)
    x0 = x_true[:, 0] + 0.3 * rng.standard_normal((B, n))
    xb, Pb = run_filter(SRUKF(model, alpha, 2.0, 0.0), model, x0, P0, u, z)
    for i in range(B):
        single = model.select(i)
        xi, Pi = run_filter(
            SRUKF(single, alpha, 2.0, 0.0), single, x0[i : i + 1], P0[i : i + 1], u[i : i + 1], z[i : i + 1]
        )
        assert relative(xb[:, i], xi[:, 0]) <= 1e-12
        assert relative(Pb[:, i], Pi[:, 0]) <= 1e-12


def test_batched_srukf_equals_each_run_alone_on_quadrotor(quadrotor_data):
    data = quadrotor_data
    u, z = quadrotor_io(data)
    n = data.model.n
    P0 = np.broadcast_to(data.P0, (2, n, n))
    xb, Pb = run_filter(SRUKF(data.model, 0.5), data.model, data.x0, P0, u, z)
    for i in range(2):
        single = data.model.select(i)
        xi, Pi = run_filter(SRUKF(single, 0.5), single, data.x0[i : i + 1], P0[i : i + 1], u[i : i + 1], z[i : i + 1])
        assert relative(xb[:, i], xi[:, 0]) <= 1e-12
        assert relative(Pb[:, i], Pi[:, 0]) <= 1e-12


def test_run_that_loses_definiteness_is_flagged_and_others_unchanged():
    """Scalar x, h(x) = x², α = 1, κ = 0, β = −3: the UT gives Pyy = σ⁴(γ² − α² + β) + R
    = −3σ⁴ + R, so the downdate of eq. 5.24 must fail for σ² = 1, R = 0.01 and succeed for
    σ² = 0.01 (Pyy = 0.0097)."""

    def f(x, u):
        return x

    def h(x, u):
        return x**2

    B = 3
    model = FunctionalModel(f, h, Q=np.array([[1e-4]]), R=np.array([[0.01]]), batch_size=B)
    P0 = np.array([[[0.01]], [[1.0]], [[0.01]]])
    x0 = np.array([[0.0], [0.0], [0.1]])
    u = np.zeros((B, 6, 0))
    z = np.full((B, 6, 1), 0.02)
    est = SRUKF(model, alpha=1.0, beta=-3.0, kappa=0.0)
    xb, _ = run_filter(est, model, x0, P0, u, z)
    assert est.failed.tolist() == [False, True, False]
    assert "indefinite" in est.failure_reasons[1]
    assert np.isfinite(xb).all()
    for i in (0, 2):
        single = model.select(i)
        xi, _ = run_filter(
            SRUKF(single, 1.0, -3.0, 0.0), single, x0[i : i + 1], P0[i : i + 1], u[i : i + 1], z[i : i + 1]
        )
        np.testing.assert_array_equal(xb[:, i], xi[:, 0])


def _extended_precision_ukf(model, x0, P0, u, z, alpha, beta, kappa):
    """A covariance-form UKF in np.longdouble (64-bit mantissa where the platform has it),
    with its own Cholesky and elimination: an independent reference, not our code path."""
    LD = np.longdouble
    n = model.n
    w = ut_weights(n, alpha, beta, kappa)
    wm, wc = w.wm.astype(LD), w.wc.astype(LD)
    gamma = np.sqrt(LD(alpha) ** 2 * (n + LD(kappa)))

    def chol(P):
        L = np.zeros_like(P)
        for j in range(P.shape[0]):
            L[j, j] = np.sqrt(P[j, j] - L[j, :j] @ L[j, :j])
            for i in range(j + 1, P.shape[0]):
                L[i, j] = (P[i, j] - L[i, :j] @ L[j, :j]) / L[j, j]
        return L

    def points(x, P):
        L = chol(P).T
        return np.concatenate([x[None], x[None] + gamma * L, x[None] - gamma * L])

    def moments(Y, noise):
        mean = (wm[:, None] * Y).sum(0)
        d = Y - mean
        return mean, (wc[:, None, None] * d[:, :, None] * d[:, None, :]).sum(0) + noise, d

    x, P = x0[0].astype(LD), P0[0].astype(LD)
    Q, R = model.Q.astype(LD), model.R.astype(LD)
    xs, Ps = [], []
    for k in range(1, z.shape[1]):
        X = model.f(points(x, P)[None], u[:, k - 1].astype(LD))[0]
        x, P, _ = moments(X, Q)
        X = points(x, P)
        y, S, dY = moments(model.h(X[None], u[:, k].astype(LD))[0], R)
        Pxy = (wc[:, None, None] * (X - x)[:, :, None] * dY[:, None, :]).sum(0)
        K = Pxy @ np.linalg.inv(S.astype(float)).astype(LD)
        for _ in range(2):  # refine the inverse in extended precision (Newton–Schulz step)
            K = K + (Pxy - K @ S) @ np.linalg.inv(S.astype(float)).astype(LD)
        x = x + K @ (z[0, k].astype(LD) - y)
        P = P - K @ S @ K.T
        xs.append(x.copy())
        Ps.append(P.copy())
    return np.array(xs), np.array(Ps)


@pytest.mark.skipif(np.finfo(np.longdouble).eps >= np.finfo(float).eps, reason="no extended precision here")
@pytest.mark.parametrize("kappa", [0.0, -1.0])
def test_srukf_matches_extended_precision_ukf_at_small_alpha(kappa):
    """At α = 1e-3 (W0(c) ≈ −1e6) the SR-UKF's means and covariances stay within round-off of an
    extended-precision covariance UKF: no sign of W0 lost, no W0 term dropped. The tolerance is
    the one of the filterpy identity, from the problem's measured round-off sensitivity."""
    model = smooth_model(5)
    rng = np.random.default_rng(5)
    P0 = random_spd(rng, 4, 0.5)[None]
    x_true, u, z = simulate(model, rng.standard_normal((1, 4)), 100, 5)
    x0 = x_true[:, 0]
    ref_x, ref_P = (a.astype(float) for a in _extended_precision_ukf(model, x0, P0, u, z, 1e-3, 2.0, kappa))
    xs, Ps = run_filter(SRUKF(model, 1e-3, 2.0, kappa), model, x0, P0, u, z)
    tol_x, tol_P = tolerances(model, x0, P0, u, z, 1e-3, 2.0, kappa)
    assert relative(xs[:, 0], ref_x) <= tol_x
    assert relative(Ps[:, 0], ref_P) <= tol_P
