"""Built-in validation: the linear and UNGM models, χ² consistency and the PCRLB."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy import stats

from helpers import compose_config, compose_settings, run_filter
from quadest.app.settings import data_settings
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.filterpy_ekf import FilterpyEKF
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.registry import build_estimator
from quadest.estimators.srukf import SRUKF
from quadest.evaluation.pcrlb import pcrlb_caption, pcrlb_is_bound, pcrlb_variances
from quadest.metrics.consistency import chi2_band, fraction_inside
from quadest.runner import run_estimator
from quadest.simulation.registry import build_data


def test_chi2_band_matches_the_reference_values():
    """χ² quantiles (docs/sources.md): n = 2, N = 50 ⇒ [1.48, 2.59]; n = 6, N = 50 ⇒ [5.08, 7.00]."""
    for dof, expected in ((2, (1.48, 2.59)), (6, (5.08, 7.00))):
        lo, hi = chi2_band(dof, 50)
        assert (round(float(lo), 2), round(float(hi), 2)) == expected


@pytest.mark.parametrize("model", ["linear", "ungm"])
@pytest.mark.slow
def test_cli_runs_validation_models(tmp_path, model):
    args = [
        f"model={model}",
        "runs=5",
        "duration=20",
        "sample_period=1",
        "progress=false",
        f"hydra.run.dir={tmp_path / model}",
    ]
    proc = subprocess.run(
        [sys.executable, "-m", "quadest.app.cli", *args], capture_output=True, text=True, cwd=tmp_path, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert "PCRLB" in proc.stdout
    for name in ("rmse_vs_time.png", "consistency.png", "errors_3sigma.png"):
        assert (tmp_path / model / "figures" / name).is_file()


@pytest.fixture(scope="module")
def linear_data():
    return build_data(compose_settings(["model=linear", "runs=50", "duration=30.0", "sample_period=0.1"]))


def kalman_reference(data):
    model = data.model
    xs, Ps = [], []
    for i in range(data.x0.shape[0]):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F, kf.H, kf.Q, kf.R = model.A, model.C, model.Q, model.R
        kf.x, kf.P = data.x0[i].copy(), data.P0.copy()
        run_x, run_P = [], []
        for k in range(1, data.time.size):
            kf.predict()
            kf.update(data.measurements[i, k])
            run_x.append(kf.x.copy())
            run_P.append(kf.P.copy())
        xs.append(run_x)
        Ps.append(run_P)
    return np.swapaxes(np.array(xs), 0, 1), np.swapaxes(np.array(Ps), 0, 1)


ESTIMATORS = {
    "ekf": lambda m: PerRunAdapter(m, FilterpyEKF),
    "ukf": lambda m: PerRunAdapter(m, FilterpyUKF, alpha=0.5),
    "srukf": lambda m: SRUKF(m, 0.5),
}


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
@pytest.mark.slow
def test_linear_model_filters_match_the_kalman_filter(linear_data, name):
    d = linear_data
    B, n = d.x0.shape
    xs, Ps = run_filter(
        ESTIMATORS[name](d.model), d.model, d.x0, np.broadcast_to(d.P0, (B, n, n)).copy(), d.inputs, d.measurements
    )
    xr, Pr = kalman_reference(d)
    assert np.abs(xs - xr).max() / np.abs(xr).max() <= 1e-9
    assert np.abs(Ps - Pr).max() / np.abs(Pr).max() <= 1e-9


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
@pytest.mark.slow
def test_linear_model_filters_are_consistent(linear_data, name):
    d = linear_data
    res = run_estimator(name, ESTIMATORS[name](d.model), d, divergence_bound=1e6)
    N = d.x0.shape[0]
    lo, hi = chi2_band(d.model.n, N)
    assert lo <= np.mean(res.mean_nees) <= hi
    lo, hi = chi2_band(d.model.m, N)
    assert lo <= np.mean(res.mean_nis) <= hi
    # 95 % of the steps should fall inside the band; allow sampling variation over 300 steps
    assert fraction_inside(res.nees_mean_t, d.model.n, res.alive_t) >= 0.85
    assert fraction_inside(res.nis_mean_t, d.model.m, res.alive_t) >= 0.85


@pytest.mark.slow
def test_pcrlb_equals_kalman_covariance_on_linear_model(linear_data):
    """For a linear-Gaussian model the information recursion is the Kalman filter's."""
    bound = pcrlb_variances(linear_data)
    _, Pr = kalman_reference(linear_data)
    diag = np.diagonal(Pr[:, 0], axis1=-2, axis2=-1)
    assert np.abs(bound[1:] - diag).max() / np.abs(diag).max() <= 1e-9


BOUNDED = [
    ["model=linear", "runs=100", "duration=3.0"],
    [
        "model=ungm",
        "runs=100",
        "duration=100",
        "sample_period=1",
        "estimator.ukf.alpha=1.0",
        "estimator.ukf.beta=0.0",
        "estimator.ukf.kappa=2.0",
        "estimator.srukf.alpha=1.0",
        "estimator.srukf.beta=0.0",
        "estimator.srukf.kappa=2.0",
    ],
    [
        "model=ungm",
        "runs=100",
        "duration=50",
        "sample_period=1",
        "model.Q=10",
        "model.x0_mean=0",
        "model.x0_var=5",
        "model.m0=0",
        "model.P0=5",
    ],
]
FAMILY_LEVEL = 0.01  # chance that a correct filter fails any comparison of one model


def pooled_mse_and_error(res) -> tuple[np.ndarray, np.ndarray]:
    """Pooled MSE per state over the runs that did not diverge (mean of the per-run time-averaged
    MSE) and its Monte Carlo standard error: the runs are independent, the steps within a run are
    not, so the error comes from the spread of the per-run values."""
    per_run = (res.rmse[~res.diverged]) ** 2
    return per_run.mean(axis=0), per_run.std(axis=0, ddof=1) / np.sqrt(per_run.shape[0])


def critical_value(comparisons: int, runs: int) -> float:
    """One-sided Student-t quantile at the family level split over the comparisons (Bonferroni)."""
    return float(stats.t.ppf(1.0 - FAMILY_LEVEL / comparisons, runs - 1))


@pytest.mark.parametrize("overrides", BOUNDED, ids=lambda o: "-".join(x.split("=")[1] for x in o[:2]))
@pytest.mark.slow
def test_no_filter_beats_the_pcrlb(overrides):
    """Where the truth follows the filter model the PCRLB bounds the MSE of any estimator, so the
    pooled MSE may sit below it only by Monte Carlo error: ``pooled ≥ floor − t·SE`` with SE the
    standard error over the runs and t the one-sided quantile at a 1 % family level. (The mean of
    positive, right-skewed per-run MSEs has a lighter lower tail than the normal, so the test is
    conservative on UNGM.) On the linear model the Kalman filter attains the bound, so the pooled
    MSE of every filter must also not exceed it by more than t·SE."""
    cfg = compose_config([*overrides, "estimator=[ekf,ukf,srukf]"])
    data = build_data(data_settings(cfg))
    assert pcrlb_is_bound(cfg.model.name)
    floor = pcrlb_variances(data)[1:].mean(axis=0)
    linear = cfg.model.name == "linear"
    comparisons = len(cfg.estimator) * data.model.n * (2 if linear else 1)
    t = critical_value(comparisons, data.x0.shape[0])
    for name, node in cfg.estimator.items():
        res = run_estimator(name, build_estimator(name, node, data.model), data, divergence_bound=1e6)
        pooled, se = pooled_mse_and_error(res)
        assert (pooled >= floor - t * se).all(), (name, (pooled - floor) / se)
        if linear:
            assert (pooled <= floor + t * se).all(), (name, (pooled - floor) / se)


@pytest.mark.slow
def test_pcrlb_is_called_a_bound_only_where_it_is_one():
    """On the quadrotor the truth is not generated by the filter model (no process noise,
    sensor errors the filter approximates by R): the SR-UKF's pooled MSE of vx, vy falls below
    the recursion there by far more than Monte Carlo error (about 0.6 of it, ten standard errors),
    so it must not be printed as a bound."""
    assert pcrlb_is_bound("linear") and pcrlb_is_bound("ungm") and not pcrlb_is_bound("quadrotor")
    assert "not a bound" in pcrlb_caption("quadrotor")
    assert "not a bound" not in pcrlb_caption("linear") and "floor" in pcrlb_caption("linear")
    cfg = compose_config(["model=quadrotor", "runs=20", "duration=3.0", "estimator=[srukf]"])
    data = build_data(data_settings(cfg))
    floor = pcrlb_variances(data)[1:].mean(axis=0)
    res = run_estimator("srukf", build_estimator("srukf", cfg.estimator.srukf, data.model), data, 1e6)
    pooled, se = pooled_mse_and_error(res)
    assert ((pooled - floor) / se).min() < -critical_value(data.model.n, 20)
