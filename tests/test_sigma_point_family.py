"""The sigma-point family: every rule in both forms, against independent references.

- Linear-Gaussian model: every filter (and its augmented form) is the Kalman filter, through the
  plugin conformance kit (filterpy's ``KalmanFilter`` is the reference).
- Random nonlinear model with correlated non-identity P0, Q, R and m < n: each square-root filter
  equals its covariance-form twin. Tolerance: relative 1e-9 (both forms do O(L n²) operations on
  O(1) numbers; round-off is ~1e-13, and a wrong column, weight or sign gives O(1) differences).
- Augmented form on an additive-noise model with κ_aug = κ − (q + r): the time update equals the
  additive filter's (the noise dimensions only move weight to the centre point).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from filterpy.kalman import KalmanFilter

from helpers import compose_config, random_spd, run_filter, simulate, smooth_model
from quadest.app.job import run_job
from quadest.app.settings import data_settings
from quadest.conformance import check_estimator
from quadest.estimators.central_difference import CDKF, SRCDKF
from quadest.estimators.cubature import CKF, CKF5, SRCKF, SRCKF5
from quadest.estimators.divided_difference import DD1
from quadest.estimators.gauss_hermite import GHKF
from quadest.estimators.sigma_point import SigmaPointKalmanFilter, SquareRootSigmaPointFilter
from quadest.estimators.srukf import SRUKF
from quadest.models.functional import FunctionalModel
from quadest.numerics import rules
from quadest.simulation.registry import build_data

FAMILY = [
    (SRUKF, {"alpha": 0.5}, [{"alpha": -1.0}, {"kappa": -10.0}]),
    (SRUKF, {"alpha": 1e-3, "beta": 2.0}, []),
    (CDKF, {}, [{"h": 0.5}]),
    (SRCDKF, {"h": 2.0}, [{"h": 0.5}]),
    (CKF, {}, []),
    (SRCKF, {}, []),
    (CKF5, {}, []),
    (SRCKF5, {}, []),
    (GHKF, {"p": 3}, [{"p": 0}]),
    (DD1, {}, [{"h": 0.9}]),
]


def _id(case) -> str:
    cls, params, _ = case
    return cls.config_name + "".join(f"-{k}{v}" for k, v in params.items())


@pytest.mark.parametrize("augmented", [False, True])
@pytest.mark.parametrize(
    "case", [pytest.param(c, id=_id(c), marks=[pytest.mark.slow] if c[0] is GHKF else []) for c in FAMILY]
)
def test_family_member_is_the_kalman_filter_on_a_linear_model(case, augmented):
    cls, params, bad = case
    # alpha = 1e-3 puts W0 near -1e6 (and -1e7 augmented): round-off grows by about |W0|.
    rtol = 1e-9 if params.get("alpha", 1.0) > 0.1 else 1e-6
    check_estimator(cls, {**params, "augmented": augmented}, bad_params=bad, rtol=rtol)


TWINS = [
    ("ut-0.5", rules.UnscentedRule(0.5, 2.0, 0.0), 4),
    ("ut-1", rules.UnscentedRule(1.0, 0.0, 0.0), 4),
    ("cd", rules.CentralDifferenceRule(), 4),
    ("cd-h2", rules.CentralDifferenceRule(2.0), 6),
    ("cubature3", rules.CubatureRule(), 4),
    ("cubature5-n4", rules.FifthDegreeCubatureRule(), 4),
    ("cubature5-n6", rules.FifthDegreeCubatureRule(), 6),
    ("gauss-hermite", rules.GaussHermiteRule(3), 4),
]


def _problem(n: int, seed: int = 11, runs: int = 3, steps: int = 40):
    model = smooth_model(seed, n=n, m=2, batch_size=runs)
    rng = np.random.default_rng(seed)
    P0 = np.broadcast_to(random_spd(rng, n, 0.5), (runs, n, n)).copy()
    x_true, u, z = simulate(model, rng.standard_normal((runs, n)), steps, seed)
    x0 = x_true[:, 0] + rng.standard_normal((runs, n)) @ np.linalg.cholesky(P0[0]).T
    return model, x0, P0, u, z


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("augmented", [False, True])
@pytest.mark.parametrize(
    ("name", "rule", "n"),
    [pytest.param(*t, id=t[0], marks=[pytest.mark.slow] if t[0] == "gauss-hermite" else []) for t in TWINS],
)
def test_square_root_form_equals_covariance_form(name, rule, n, augmented):
    model, x0, P0, u, z = _problem(n)
    cov = SigmaPointKalmanFilter(model, rule, augmented)
    sqrt = SquareRootSigmaPointFilter(model, rule, augmented)
    xc, Pc = run_filter(cov, model, x0, P0, u, z)
    xs, Ps = run_filter(sqrt, model, x0, P0, u, z)
    assert not cov.failed.any() and not sqrt.failed.any()
    assert relative(xs, xc) <= 1e-9
    assert relative(Ps, Pc) <= 1e-9


def test_srukf_is_the_square_root_filter_with_the_unscented_rule():
    model, x0, P0, u, z = _problem(4)
    a = run_filter(SRUKF(model, 0.3, 2.0, 1.0), model, x0, P0, u, z)
    b = run_filter(SquareRootSigmaPointFilter(model, rules.UnscentedRule(0.3, 2.0, 1.0)), model, x0, P0, u, z)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_square_root_central_difference_filter_never_downdates(monkeypatch):
    """van der Merwe 2004 (SR-CDKF): every SR-CDKF column is added; a call of cholupdate with a
    negative sign would mean a downdate crept in."""
    import quadest.estimators.sigma_point as sp

    calls = []
    real = sp.cholupdate

    def spy(S, u, sign):
        calls.append(sign)
        return real(S, u, sign)

    monkeypatch.setattr(sp, "cholupdate", spy)
    model, x0, P0, u, z = _problem(4)
    run_filter(SRCDKF(model), model, x0, P0, u, z)
    assert calls == []
    run_filter(SRUKF(model, 1e-3, 2.0, 0.0), model, x0, P0, u, z)
    assert -1.0 in calls  # the spy sees the SR-UKF's W0 and posterior downdates


@pytest.mark.parametrize(
    ("rule", "rule_aug"),
    [
        (rules.UnscentedRule(0.5, 2.0, 0.0), "kappa"),
        (rules.UnscentedRule(1.0, 0.0, 1.0), "kappa"),
    ],
)
def test_augmented_time_update_equals_additive_with_shifted_kappa(rule, rule_aug):
    """κ_aug = κ − (q + r) keeps γ² = α²(n + κ); the noise points then carry Q exactly and the
    measurement-noise points only move weight to the centre, so one predict gives the same mean
    and covariance as the additive filter (van der Merwe 2004)."""
    n = 4
    model, x0, P0, u, _ = _problem(n)
    q, r = model.process_noise_dim, model.measurement_noise_dim
    aug_rule = rules.UnscentedRule(rule.alpha, rule.beta, rule.kappa - (q + r))
    for form in (SigmaPointKalmanFilter, SquareRootSigmaPointFilter):
        add, aug = form(model, rule), form(model, aug_rule, augmented=True)
        add.initialize(x0, P0)
        aug.initialize(x0, P0)
        add.predict(u[:, 0])
        aug.predict(u[:, 0])
        assert relative(aug.mean, add.mean) <= 1e-12
        assert relative(aug.covariance, add.covariance) <= 1e-12


def test_augmented_filter_uses_the_models_noise_functions():
    """A model with multiplicative process noise x⁺ = x (1 + w), x ~ N(m, P), w ~ N(0, Q): the
    predicted variance is E[x²(1 + w)²] − m² = P + (m² + P) Q. The integrand has degree 4 with the
    cross term x²w², so the fifth-degree rule is exact (the third-degree rule misses P·Q)."""

    class Multiplicative(FunctionalModel):
        def f_noise(self, x, w, u):
            return x * (1.0 + w)

    Q, P, mean = 0.04, 0.3, 1.5
    model = Multiplicative(lambda x, u: x, lambda x, u: x, np.array([[Q]]), np.array([[1.0]]))
    est = CKF5(model, augmented=True)
    est.initialize(np.array([[mean]]), np.array([[[P]]]))
    est.predict(np.zeros((1, 0)))
    assert np.isclose(est.mean[0, 0], mean, rtol=1e-14)
    assert np.isclose(est.covariance[0, 0, 0], (mean**2 + P) * Q + P, rtol=1e-13)


def test_model_without_augmented_support_is_refused():
    model = smooth_model(0)
    model.supports_augmented = False
    with pytest.raises(ValueError, match="does not support augmented"):
        SRCKF(model, augmented=True)


def test_covariance_form_fifth_degree_flags_lost_definiteness_without_crashing():
    """n = 9 (axis weights −5/242): a strongly quartic f makes the covariance-form CKF5's predicted
    covariance indefinite in the run with a wide prior; that run is flagged, the others run
    on, and the square-root form flags them through a failed downdate."""
    n, runs = 9, 3

    def f(x, u):
        return x + 0.5 * x**4

    model = FunctionalModel(f, lambda x, u: x[..., :2], 1e-4 * np.eye(n), 1e-2 * np.eye(2), batch_size=runs)
    x0 = np.zeros((runs, n))
    x0[1, 0] = 3.0
    P0 = np.broadcast_to(np.eye(n) * np.array([1e-4, 1e-4, 0.5])[:, None, None], (runs, n, n)).copy()
    P0[1] = 0.5 * np.eye(n)
    for cls in (CKF5, SRCKF5):
        est = cls(model)
        est.initialize(x0, P0)
        for _ in range(3):
            est.predict(np.zeros((runs, 0)))
            est.update(np.zeros((runs, 2)), np.zeros((runs, 0)))
        assert est.failed[2] and not est.failed[0], (cls.__name__, est.failed, est.failure_reasons)
        assert np.isfinite(est.mean).all()


def test_rank_deficient_process_noise_is_accepted_and_indefinite_refused():
    """√Q needs only Q ⪰ 0 (thesis §5.2.3): a rank-one Q runs in every form and the SR-UKF still
    equals its covariance twin; an indefinite Q is refused with a message."""
    n = 4
    model, x0, P0, u, z = _problem(n)
    v = np.arange(1.0, n + 1.0)[:, None]
    model.Q = 1e-3 * (v @ v.T)
    rule = rules.UnscentedRule(0.5, 2.0, 0.0)
    xc, Pc = run_filter(SigmaPointKalmanFilter(model, rule), model, x0, P0, u, z)
    xs, Ps = run_filter(SRUKF(model), model, x0, P0, u, z)
    assert relative(xs, xc) <= 1e-9 and relative(Ps, Pc) <= 1e-9
    model.Q = np.diag([1.0, 1.0, 1.0, -0.1])
    with pytest.raises(ValueError, match="Q must be positive semi-definite"):
        SRUKF(model)


def test_ghkf_with_ten_points_is_exact_on_a_scalar_polynomial():
    """x ~ N(m, P), f(x) = x³: E[f] = m³ + 3mP and Var[f] = 9m⁴P + 36m²P² + 15P³ (Gaussian
    moments); a 10-point Gauss–Hermite rule is exact to degree 19."""
    m_, P = 0.7, 0.2
    model = FunctionalModel(lambda x, u: x**3, lambda x, u: x, np.array([[1e-9]]), np.array([[1.0]]))
    est = GHKF(model, p=10)
    est.initialize(np.array([[m_]]), np.array([[[P]]]))
    est.predict(np.zeros((1, 0)))
    assert np.isclose(est.mean[0, 0], m_**3 + 3 * m_ * P, rtol=1e-13)
    var = 9 * m_**4 * P + 36 * m_**2 * P**2 + 15 * P**3 + 1e-9
    assert np.isclose(est.covariance[0, 0, 0], var, rtol=1e-12)


def test_dd1_keeps_first_order_terms_only_and_cdkf_the_second_order_too():
    """x ~ N(m, P), f(x) = x²: E[f] = m² + P and Var[f] = 4m²P + 2P². The CDKF (DD2) is exact for
    the mean of a quadratic and gets 4m²P + (h² − 1)P² for the variance (by hand, n = 1:
    A1 = 2m√P, A2 = √(h² − 1)P); DD1 gives f(m) = m² and 4m²P (first-order terms only)."""
    m_, P, h = 0.8, 0.3, 1.7
    model = FunctionalModel(lambda x, u: x**2, lambda x, u: x, np.array([[1e-12]]), np.array([[1.0]]))
    for cls, mean, var in (
        (CDKF, m_**2 + P, 4 * m_**2 * P + (h**2 - 1) * P**2),
        (DD1, m_**2, 4 * m_**2 * P),
    ):
        est = cls(model, h=h)
        est.initialize(np.array([[m_]]), np.array([[[P]]]))
        est.predict(np.zeros((1, 0)))
        assert np.isclose(est.mean[0, 0], mean, rtol=1e-13), cls.__name__
        assert np.isclose(est.covariance[0, 0, 0], var + 1e-12, rtol=1e-12), cls.__name__


@pytest.mark.integration
@pytest.mark.slow
def test_linear_command_every_family_filter_matches_the_kalman_filter(tmp_path):
    """The family's acceptance command, ``quadest model=linear sample_period=0.1 duration=30
    estimator=[ukf,srukf,cdkf,srcdkf,ckf,srckf,ckf5,srckf5,ghkf]`` (3 runs here), through the job:
    every estimator's per-run RMSE equals that of filterpy's KalmanFilter on the same data."""
    names = ["ukf", "srukf", "cdkf", "srcdkf", "ckf", "srckf", "ckf5", "srckf5", "ghkf"]
    overrides = ["model=linear", "sample_period=0.1", "duration=30", "runs=3", "progress=false", "workers=1"]
    cfg = compose_config([*overrides, f"estimator=[{','.join(names)}]", "output.saved_runs=0"])
    run_job(cfg, tmp_path)
    table = pd.read_csv(tmp_path / "metrics.csv")
    data = build_data(data_settings(cfg))
    model = data.model
    B, K1, n = data.truth.shape
    sq = np.zeros((B, n))
    for i in range(B):
        kf = KalmanFilter(dim_x=n, dim_z=model.m)
        kf.F, kf.H, kf.Q, kf.R = model.A, model.C, model.Q, model.R
        kf.x, kf.P = data.x0[i].copy(), data.P0.copy()
        for k in range(1, K1):
            kf.predict()
            kf.update(data.measurements[i, k])
            sq[i] += (kf.x - data.truth[i, k]) ** 2
    reference = np.sqrt(sq / (K1 - 1))
    filt = table[table.quantity == "filter"]
    for name in names:
        got = filt[filt.estimator == name].pivot(index="run", columns="state", values="rmse")[list(model.state_names)]
        assert np.allclose(got.to_numpy(), reference, rtol=1e-9, atol=0), name
