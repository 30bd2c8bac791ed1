"""Tests that fail when the science breaks: divergence bookkeeping against hand-computed
values, the truth-side MIMU errors against hand-computed values, and common random numbers
between estimators of different kinds."""

from __future__ import annotations

from dataclasses import replace
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest

from helpers import compose_config, compose_settings
from quadest.app.job import run_job
from quadest.estimators.base import Estimator
from quadest.evaluation.metrics import floor_table, summarize, tidy_metrics
from quadest.runner import run_estimator
from quadest.sensors.mimu import TriadErrors, TriadSpec, draw_triad_errors, measure_triad
from quadest.simulation.registry import build_data

# --- 1. diverged runs leave the RMSE at the step they diverge ------------------------------------

BOUND = 10.0
K = 6


def scripted_errors() -> np.ndarray:
    """(B=3, K+1, n=4) estimation errors. Run 0: 0.1 throughout. Run 1: 0.2 at steps 1–3, 50 in
    one state at step 4 (beyond the bound), 0.3 afterwards. Run 2: 0.05 at step 1; the estimator
    flags it at step 2, with errors of 0.4 from then on."""
    e = np.zeros((3, K + 1, 4))
    e[0, 1:] = 0.1
    e[1, 1:4] = 0.2
    e[1, 4] = [50.0, 0.2, 0.2, 0.2]
    e[1, 5:] = 0.3
    e[2, 1] = 0.05
    e[2, 2:] = 0.4
    return e


class Scripted(Estimator):
    """Reports truth + the scripted error of each step with covariance I; flags run 2 at step 2."""

    capabilities: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, model, errors: np.ndarray) -> None:
        super().__init__(model)
        self.errors, self.k = errors, 0

    def initialize(self, x0, P0):
        self._reset_failures(x0.shape[0])

    def predict(self, u):
        self.k += 1

    def update(self, z, u):
        if self.k == 2:
            self.flag([2], "scripted failure")

    @property
    def mean(self):
        return self.errors[:, self.k]

    @property
    def covariance(self):
        return np.broadcast_to(np.eye(4), (3, 4, 4)).copy()


@pytest.fixture(scope="module")
def scripted_run():
    data = build_data(compose_settings(["model=linear", "runs=3", f"duration={K}", "sample_period=1"]))
    data = replace(data, truth=np.zeros_like(data.truth))
    return data, run_estimator("scripted", Scripted(data.model, scripted_errors()), data, divergence_bound=BOUND)


def test_a_run_diverging_midway_counts_only_its_steps_before_divergence(scripted_run):
    _, res = scripted_run
    assert res.diverged.tolist() == [False, True, True]
    assert res.diverged_step.tolist() == [-1, 4, 2]
    assert "divergence_bound" in res.reasons[1] and res.reasons[2] == "scripted failure"
    assert res.steps.tolist() == [6, 3, 1]
    np.testing.assert_allclose(res.sq_error_sum, [[0.06] * 4, [0.12] * 4, [0.0025] * 4], rtol=1e-12)
    np.testing.assert_allclose(res.nees_sum, [6 * 0.04, 3 * 0.16, 0.01], rtol=1e-12)
    assert res.alive_t[1:].tolist() == [3, 2, 2, 1, 1, 1]
    expected_t = np.array([0.01 + 0.04 + 0.0025, 0.05, 0.05, 0.01, 0.01, 0.01])
    np.testing.assert_allclose(res.sq_error_t[1:], np.repeat(expected_t[:, None], 4, axis=1), rtol=1e-12)
    np.testing.assert_allclose(res.rmse[0], 0.1, rtol=1e-12)
    assert np.isnan(res.rmse[1:]).all() and np.isnan(res.mean_nees[1:]).all()


def test_summary_tables_exclude_the_diverged_runs(scripted_run):
    data, res = scripted_run
    table = tidy_metrics([res], data, {}, {"seed": 0, "runs": 3})
    summary = summarize(table)
    filt = summary[summary["quantity"] == "filter"]
    np.testing.assert_allclose(filt["rmse_mean"], 0.1, rtol=1e-12)
    np.testing.assert_allclose(filt["mse_mean"], 0.01, rtol=1e-12)
    assert (filt["runs"] == 1).all() and (filt["diverged"] == 2).all()
    pooled = floor_table([res], data, np.ones((K + 1, 4)))["pooled_rmse"]
    np.testing.assert_allclose(pooled, np.sqrt((0.0525 + 0.05 + 0.05 + 0.03) / 10), rtol=1e-12)


# --- 2. the MIMU errors on the truth side ---------------------------------------------------------

S = np.array([0.01, -0.02, 0.03])  # scale-factor errors
ASYM = np.array([0.004, -0.006, 0.008])
CROSS = {(0, 1): 0.004, (0, 2): -0.002, (1, 0): 0.001, (1, 2): 0.003, (2, 0): -0.005, (2, 1): 0.006}
BIAS = np.array([0.1, -0.2, 0.3])


def hand_measured(y: list[float]) -> list[float]:
    """ỹ_i = y_i + S_i y_i + S±_i |y_i| + Σ_j M_ij y_j + b_i, axis by axis (module docstring of
    quadest.sensors.mimu)."""
    out = []
    for i in range(3):
        value = y[i] + S[i] * y[i] + ASYM[i] * abs(y[i]) + BIAS[i]
        for j in range(3):
            value += CROSS.get((i, j), 0.0) * y[j]
        out.append(value)
    return out


def test_measure_triad_applies_the_deterministic_errors_as_documented():
    M = np.eye(3) + np.diag(S)
    for (i, j), v in CROSS.items():
        M[i, j] = v
    errors = TriadErrors(M[None], ASYM[None], BIAS[None])
    y = np.array([[[2.0, -1.0, 0.5], [-3.0, 4.0, -0.25], [0.0, 0.0, 0.0]]])
    got = measure_triad(TriadSpec(), errors, y, 0.01, [np.random.default_rng(0)])
    expected = [hand_measured(list(row)) for row in y[0]]
    np.testing.assert_allclose(got[0], expected, rtol=1e-14, atol=1e-15)
    # e.g. x axis at sample 0: 2 + 0.02 + 0.008 + 0.004·(−1) − 0.002·0.5 + 0.1 = 2.123
    assert got[0, 0, 0] == pytest.approx(2.123, abs=1e-14)


RUNS = 4000


def five_sigma_variance(sample: np.ndarray, variance: float) -> None:
    """The sample variance of N zero-mean Gaussian values has relative standard error √(2/N)."""
    assert abs(np.mean(sample**2) / variance - 1.0) <= 5.0 * np.sqrt(2.0 / sample.size)


def test_measure_triad_random_drift_and_white_noise_have_the_documented_variances():
    """Drift: a random walk from 0 with σ_bc √T per sample, so var(b_k) = k σ_bc² T; white noise
    σ_c / √T. 4000 runs × 3 axes per step; five standard errors of a sample variance."""
    T, walk, white = 0.01, 0.3, 0.05
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(7).spawn(RUNS)]
    zero = np.zeros((RUNS, 11, 3))
    nominal = TriadErrors.nominal(RUNS)
    drift = measure_triad(TriadSpec(bias_random_walk=walk), nominal, zero, T, rngs)
    assert (drift[:, 0] == 0).all()
    for k in (1, 4, 10):
        five_sigma_variance(drift[:, k], k * walk**2 * T)
    noise = measure_triad(TriadSpec(white_noise=white), nominal, zero, T, rngs)
    for k in (0, 5, 10):
        five_sigma_variance(noise[:, k], white**2 / T)


def test_draw_triad_errors_have_the_documented_spreads():
    spec = TriadSpec(scale_factor=0.01, asymmetry=0.003, cross_coupling=0.005, bias=0.2)
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(8).spawn(RUNS)]
    e = draw_triad_errors(spec, rngs)
    off = ~np.eye(3, dtype=bool)
    five_sigma_variance(np.diagonal(e.matrix, axis1=1, axis2=2) - 1.0, spec.scale_factor**2)
    five_sigma_variance(e.matrix[:, off], spec.cross_coupling**2)
    five_sigma_variance(e.asymmetry, spec.asymmetry**2)
    five_sigma_variance(e.bias, spec.bias**2)


# --- 3. common random numbers between estimators of different kinds -----------------------------

PLUGIN = ["+estimator.plugin._target_=target_plugin.LinearizedKF"]


def test_estimators_of_every_kind_see_the_same_draws_on_the_linear_model(tmp_path):
    """On model=linear the EKF, UKF, SR-UKF, CKF and a _target_ plugin all equal the Kalman
    filter (to 1e-9, tests/test_validation_models.py), so on common data their per-run RMSEs agree
    to that precision; data drawn per estimator (other measurement noise, truth or x0) changes
    them at order one."""
    cfg = compose_config(
        ["model=linear", "runs=4", "duration=5", "sample_period=0.1", "progress=false", "output.figures=false",
         "workers=1", "estimator=[ekf,ukf,srukf,ckf]", *PLUGIN]
    )  # fmt: skip
    run_job(cfg, tmp_path / "job")
    table = pd.read_csv(tmp_path / "job" / "metrics.csv")
    rmse = table[table["quantity"] == "filter"].pivot_table(index=["run", "state"], columns="estimator", values="rmse")
    assert sorted(rmse.columns) == ["ckf", "ekf", "plugin", "srukf", "ukf"]
    reference = rmse["srukf"].to_numpy()
    for name in rmse.columns:
        assert np.abs(rmse[name].to_numpy() - reference).max() <= 1e-9 * reference.max(), name


def test_estimators_of_every_kind_get_identical_data_on_the_quadrotor(tmp_path, monkeypatch):
    """What each estimator is run on, recorded at the runner's door: the same truth, inputs,
    measurements, x0 and P0 for the EKF, UKF, SR-UKF and a plugin."""
    import quadest.app.estimator_runs

    seen = {}

    def recording(name, est, data, *args, **kwargs):
        seen[name] = data
        return run_estimator(name, est, data, *args, **kwargs)

    monkeypatch.setattr(quadest.app.estimator_runs, "run_estimator", recording)
    cfg = compose_config(
        ["runs=2", "duration=0.3", "progress=false", "output.figures=false", "workers=1",
         "estimator=[ekf,ukf,srukf]", *PLUGIN]
    )  # fmt: skip
    run_job(cfg, tmp_path / "job")
    assert sorted(seen) == ["ekf", "plugin", "srukf", "ukf"]
    first = seen["srukf"]
    for name, data in seen.items():
        for field in ("truth", "companion_truth", "inputs", "measurements", "x0", "P0", "companion0"):
            np.testing.assert_array_equal(getattr(data, field), getattr(first, field), err_msg=f"{name}.{field}")
