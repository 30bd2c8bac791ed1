"""The χ² consistency bands of the summary, as a property over every registered model.

``summary.json`` (and the printed per-estimator line) gives, per estimator, the share of time
steps whose run-averaged NEES and NIS lie inside their two-sided 95 % band
(``quadest.metrics.consistency``; Bar-Shalom, Li & Kirubarajan 2001, §5.4.2): averaged over the N runs
alive at step k, ``N·ε̄_k ~ χ²(N·d)``, with d the dimension of the estimation error (NEES) or of
the primary measurement (NIS). The two dimensions differ on most models (``model=linear``: 4
states, 2 measured positions; ``model=attitude``: 9 error states, 3 accelerometer axes), and a
band taken with the wrong one is a different band. Here the shares the job writes are compared with
shares computed from scipy's χ² quantiles with each model's own dimensions, on statistics chosen so
that the two dimensions give different shares.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from helpers import compose_settings
from quadest.evaluation.job_tables import estimator_entries, metric_tables
from quadest.montecarlo.results import failed_result
from quadest.simulation.registry import build_data, model_specs

MODELS = sorted(model_specs())
RUNS = 3


def expected_share(average_t: np.ndarray, alive_t: np.ndarray, dof: int) -> float:
    """Share of the steps 1..K (with a live run and a finite statistic) inside
    ``[χ²(N d, 0.025)/N, χ²(N d, 0.975)/N]``, N the runs alive at the step; NaN without any."""
    inside = []
    for k in range(1, average_t.size):
        N, value = int(alive_t[k]), average_t[k]
        if N == 0 or not np.isfinite(value):
            continue
        inside.append(chi2.ppf(0.025, N * dof) / N <= value <= chi2.ppf(0.975, N * dof) / N)
    return float(np.mean(inside)) if inside else float("nan")


def synthetic_result(data, nees_t: np.ndarray, nis_t: np.ndarray, alive_t: np.ndarray):
    """An estimator result with the given per-step averages and live-run counts (no estimator runs)."""
    base = failed_result("probe", data, "unused")
    B, K1, n = data.truth.shape[0], data.truth.shape[1], data.model.n_err
    return dataclasses.replace(
        base, diverged=np.zeros(B, dtype=bool), diverged_step=np.full(B, -1), reasons={}, steps=np.full(B, K1 - 1.0),
        sq_error_sum=np.ones((B, n)), nees_sum=np.full(B, float(K1 - 1)), nis_sum=np.full(B, float(K1 - 1)),
        nees_mean_t=nees_t, nis_mean_t=nis_t, alive_t=alive_t, step_time_us=1.0,
        derived_sq_error_sum=np.ones((B, len(data.model.derived_error_names))),
        companion_sq_error_sum=np.ones((B, data.companion_truth.shape[-1])),
    )  # fmt: skip


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.slow
def test_band_shares_use_the_error_dimension_for_nees_and_the_measurement_dimension_for_nis(model):
    """The shares in the summary entry equal the shares of scipy's χ² quantiles with d = the
    model's error dimension (NEES) and its primary measurement dimension (NIS; a model without a
    primary measurement has no NIS and no share)."""
    data = build_data(
        compose_settings([f"model={model}", f"runs={RUNS}", "duration=0.3", "sample_period=0.01", "progress=false"])
    )
    n, m = data.model.n_err, data.model.m
    K1 = data.time.size
    alive_t = np.resize([RUNS, RUNS, 2, 1, 0], K1).astype(float)  # runs dropping out, a step with none alive
    top = 3.0 * max(n, m)
    nees_t = np.linspace(0.0, top, K1)  # from below every band to above it
    nis_t = np.linspace(0.0, top, K1)[::-1].copy() if m else np.full(K1, np.nan)
    nees_t[7] = np.nan  # a step without the statistic does not count
    result = synthetic_result(data, nees_t, nis_t, alive_t)
    params = {"probe": {"kind": "probe"}}
    tables = metric_tables([result], data, params, {}, np.full((K1, n), np.nan))
    entry = estimator_entries([result], tables, params, {"probe": False})["probe"]

    assert entry["nees_in_band"] == pytest.approx(expected_share(nees_t, alive_t, n), abs=0)
    if m:
        assert entry["nis_in_band"] == pytest.approx(expected_share(nis_t, alive_t, m), abs=0)
    else:
        assert entry["nis_in_band"] is None
    if m and m != n:  # the statistics tell the dimensions apart: a share with the other one differs
        assert expected_share(nis_t, alive_t, n) != expected_share(nis_t, alive_t, m)
        assert expected_share(nees_t, alive_t, m) != expected_share(nees_t, alive_t, n)


@pytest.mark.slow
def test_the_family_has_models_whose_dimensions_differ():
    """The property above has teeth only where n ≠ m: the registered family has such models."""
    dims = {}
    for model in MODELS:
        data = build_data(
            compose_settings([f"model={model}", "runs=1", "duration=0.05", "sample_period=0.01", "progress=false"])
        )
        dims[model] = (data.model.n_err, data.model.m)
    assert any(m and n != m for n, m in dims.values()), dims
