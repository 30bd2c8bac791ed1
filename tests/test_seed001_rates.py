"""Seed 001's rate model as the truth (Li & Liang 2015, §3.1): the rates follow the filters' own
Euler model driven by N(0, Q) process noise, so the PCRLB beside the table is a bound that no
filter may beat beyond Monte Carlo error."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.estimators.registry import build_estimator
from quadest.evaluation.pcrlb import pcrlb_is_bound, pcrlb_variances
from quadest.montecarlo.streams import run_streams
from quadest.runner import run_estimator
from quadest.simulation.registry import build_data

FAMILY_LEVEL = 0.01  # chance that correct filters fail any comparison of the bound test
RUNS, DURATION = 30, 3.0  # 150 steps of 20 ms, through the tilt at 2 s
FILTERS = ["ekf", "pf_100", "ekpf_100", "ilopf_100", "ilopf_uniform_100", "upf_100"]


@pytest.fixture(scope="module")
def seed001():
    cfg = compose_config(["experiment=seed001_rates", f"runs={RUNS}", f"duration={DURATION}"])
    return cfg, build_data(data_settings(cfg))


def test_truth_is_the_filter_model_driven_by_the_process_streams_draws(seed001):
    """Every increment ``x_k − f(x_{k−1}, Ω_{k−1})`` is √Q times the run's ``process`` stream draw
    (recomputed here from the seed): the truth is the seed's model, not the flown rates. Round-off:
    one addition and one subtraction of numbers below 20 rad/s, far below 1e-12."""
    cfg, data = seed001
    model, x, u = data.model, data.truth, data.inputs
    increments = np.stack([x[:, k] - model.f(x[:, k - 1][:, None], u[:, k - 1])[:, 0] for k in range(1, x.shape[1])], 1)
    draws = np.stack([rng.standard_normal((x.shape[1], 3)) for rng in run_streams(int(cfg.seed), RUNS)["process"]])
    np.testing.assert_allclose(increments, np.sqrt(float(cfg.model.Q)) * draws[:, 1:], rtol=0, atol=1e-12)
    assert pcrlb_is_bound(cfg.model.name, data.labels)


@pytest.mark.slow
def test_no_filter_beats_the_pcrlb_beyond_monte_carlo_error(seed001):
    """The pooled MSE per axis (mean over runs of the per-run time-averaged squared error) may sit
    below the time-averaged bound only by Monte Carlo error: ``pooled ≥ floor − t·SE``, SE the
    standard error over the independent runs (steps within a run are correlated, so the spread of
    the per-run values is used), t the one-sided Student-t quantile at a 1 % family level split
    over filters × axes (Bonferroni). The particle filters start on [0, 1] and resample by roulette
    wheel, as in the experiment."""
    cfg, data = seed001
    floor = pcrlb_variances(data)[1:].mean(axis=0)
    t = stats.t.ppf(1.0 - FAMILY_LEVEL / (len(FILTERS) * data.model.n), RUNS - 1)
    for name in FILTERS:
        res = run_estimator(name, build_estimator(name, cfg.estimator[name], data.model), data, 1e6)
        assert not res.diverged.any(), name
        per_run = res.rmse**2
        pooled, se = per_run.mean(axis=0), per_run.std(axis=0, ddof=1) / np.sqrt(RUNS)
        assert (pooled >= floor - t * se).all(), (name, (pooled - floor) / se)
