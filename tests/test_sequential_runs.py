"""``runs=auto`` end to end (:mod:`quadest.app.sequential_runs`, docs/experiments.md):

- a run's draws do not depend on how many runs the job has, nor on the batch it is made in: runs
  0..49 of a 100-run job are the 50-run job's, runs 50..99 the batch that starts at run 50; the
  estimators' per-run results on two batches are those on the whole;
- identical filters (the UKF and the SR-UKF with the same α, β, κ on the linear model, equal in
  exact arithmetic) end *equivalent* at the first look, through the ``quadest`` command;
- the first batch is the job with ``runs = decision.batch`` (its numbers, from the cache), and the
  same job again computes nothing;
- bad ``runs`` and ``decision.*`` values are refused with one line before any work.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from helpers import compose_config, compose_settings
from quadest.app.estimator_runs import OnData, RunSettings
from quadest.app.job import run_job
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.montecarlo.batches import concatenate_results
from quadest.simulation.registry import build_data

ARRAYS = ("truth", "companion_truth", "inputs", "measurements", "x0", "companion0")
SMALL = {
    "linear": ["model=linear", "duration=2", "sample_period=0.5"],
    "quadrotor": ["duration=0.2"],
    "ungm": ["model=ungm", "duration=2", "sample_period=1"],
    "attitude": ["model=attitude", "estimator=[mekf]", "duration=0.2"],
    "ins": ["experiment=ins_figure8", "duration=0.2"],
    "seed001_rates": ["experiment=seed001_rates", "duration=0.2"],
    "upf_benchmark": ["model=upf_benchmark", "duration=2", "sample_period=1"],
    "seed003_attitude": ["model=seed003_attitude", "scenario=attitude_steps", "estimator=[ekf]", "duration=0.2"],
}


def _batch(overrides: list[str], runs: int, first_run: int = 0):
    return build_data(dataclasses.replace(compose_settings([*overrides, f"runs={runs}"]), first_run=first_run))


def _same_data(part, whole, runs: slice) -> None:
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(part, name), getattr(whole, name)[runs], err_msg=name)
    for sensor, record in part.sensors.items():
        np.testing.assert_array_equal(record.values, whole.sensors[sensor].values[runs], err_msg=sensor)
    seeds = zip(part.estimator_seeds, whole.estimator_seeds[runs], strict=True)
    assert all(a.spawn_key == b.spawn_key and a.entropy == b.entropy for a, b in seeds)


def test_the_first_fifty_runs_of_a_hundred_run_job_are_the_fifty_run_job():
    """Runs 0..49 of a 100-run job equal the 50-run job's, and runs 50..99 the batch of 50 runs
    from run 50 on, array for array, bit for bit."""
    whole, first, second = _batch(SMALL["linear"], 100), _batch(SMALL["linear"], 50), _batch(SMALL["linear"], 50, 50)
    _same_data(first, whole, slice(0, 50))
    _same_data(second, whole, slice(50, 100))
    assert not np.array_equal(first.truth, second.truth)


@pytest.mark.parametrize("model", sorted(set(SMALL) - {"linear"}))
@pytest.mark.slow
def test_every_builder_makes_a_batch_from_its_own_runs(model):
    """Each data builder honours ``DataSettings.first_run`` (every stream, the sensors' included)."""
    whole, second = _batch(SMALL[model], 4), _batch(SMALL[model], 2, 2)
    _same_data(second, whole, slice(2, 4))


@pytest.mark.parametrize("label", ["ukf", "pf"])
def test_results_on_two_batches_are_the_results_on_all_runs(label):
    """An estimator's per-run results do not depend on the runs batched with them (the particle
    filter draws from each run's own stream), and the concatenated batch results are the result
    on all runs: per-run values bit for bit, per-step sums to round-off (summed in another order)."""
    overrides = [*SMALL["quadrotor"], f"estimator=[{label}]"]
    cfg = compose_config([*overrides, "runs=4"])
    node = {k: v for k, v in dict(cfg.estimator[label]).items()}
    settings = RunSettings(50.0, 1)
    whole = OnData(_batch(overrides, 4)).run(label, node, settings)
    parts = [OnData(_batch(overrides, 2, first)).run(label, node, settings) for first in (0, 2)]
    joined = concatenate_results(parts)
    for name in ("sq_error_sum", "steps", "nees_sum", "nis_sum", "diverged", "derived_sq_error_sum"):
        np.testing.assert_array_equal(getattr(joined, name), getattr(whole, name), err_msg=name)
    for name in ("sq_error_t", "alive_t", "nees_mean_t", "nis_mean_t"):
        np.testing.assert_allclose(getattr(joined, name), getattr(whole, name), rtol=1e-12, err_msg=name)
    np.testing.assert_array_equal(joined.saved["estimate"], whole.saved["estimate"])


AUTO = ["model=linear", "duration=2", "sample_period=0.1", "progress=false", "output.figures=false",
        "decision.batch=4", "decision.max_runs=12"]  # fmt: skip


@pytest.mark.slow
def test_identical_filters_end_equivalent_at_the_first_look(tmp_path):
    """Through the ``quadest`` command: the UKF and the SR-UKF are the same filter in exact
    arithmetic, so every state's interval is [0, 0] at the first look and the job stops there."""
    out = tmp_path / "run"
    env = {**os.environ, "HYDRA_FULL_ERROR": "0", "QUADEST_CACHE_DIR": str(tmp_path / "cache")}
    proc = subprocess.run(
        [sys.executable, "-m", "quadest.app.cli", *AUTO, "estimator=[ukf,srukf]", "runs=auto", f"hydra.run.dir={out}"],
        cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    decisions = pd.read_csv(out / "decisions.csv")
    assert list(decisions.columns) == ["pair", "state", "verdict", "runs", "estimate", "ci_low", "ci_high", "margin"]
    assert set(decisions["pair"]) == {"srukf - ukf"}
    assert (decisions["verdict"] == "equivalent").all() and (decisions["runs"] == 4).all()
    assert (decisions[["estimate", "ci_low", "ci_high"]] == 0).all().all()
    assert "Decisions (runs=auto" in proc.stdout and "equivalent" in proc.stdout
    assert json.loads((out / "summary.json").read_text())["labels"]["runs"] == 4
    assert pd.read_csv(out / "metrics.csv")["run"].max() == 3


@pytest.mark.slow
def test_the_first_batch_is_the_fixed_job_and_a_second_auto_job_computes_nothing(tmp_path):
    """A job with ``runs = decision.batch`` and an auto job of two batches (the EKF and the UKF on
    the UNGM benchmark, far from decided after 4 runs): the auto job's first runs have the fixed
    job's RMSEs; the same auto job again loads every batch and decides the same."""
    common = ["model=ungm", "duration=20", "sample_period=1", "progress=false", "output.figures=false",
              "estimator=[ekf,ukf]", "decision.batch=4", f"cache.dir={tmp_path / 'cache'}"]  # fmt: skip
    fixed = run_job(compose_config([*common, "runs=4"]), tmp_path / "fixed")
    auto = [*common, "runs=auto", "decision.max_runs=8"]
    first = run_job(compose_config(auto), tmp_path / "auto")
    again = run_job(compose_config(auto), tmp_path / "again")
    key = ["estimator", "run", "state"]
    rows = pd.read_csv(tmp_path / "auto" / "metrics.csv").set_index(key)["rmse"]
    alone = pd.read_csv(tmp_path / "fixed" / "metrics.csv").set_index(key)["rmse"]
    assert first["labels"]["runs"] == 8 and fixed["labels"]["runs"] == 4
    pd.testing.assert_series_equal(rows.loc[alone.index], alone)
    assert again["cache"]["data_from_cache"] and all(e["from_cache"] for e in again["estimators"].values())
    pd.testing.assert_frame_equal(
        pd.read_csv(tmp_path / "again" / "decisions.csv"), pd.read_csv(tmp_path / "auto" / "decisions.csv")
    )


@pytest.mark.parametrize(
    ("overrides", "key"),
    [
        (["decision.batch=1"], "decision.batch"),
        (["decision.margin=0"], "decision.margin"),
        (["decision.alpha=1.5"], "decision.alpha"),
        (["decision.max_runs=30"], "decision.max_runs"),
        (["decision.max_runs=75"], "decision.max_runs"),
        (["decision.pairs=[ukf - nope]"], "decision.pairs"),
        (["decision.pairs=[ukf]"], "decision.pairs"),
        (["decision.pairs=[ukf - ukf]"], "decision.pairs"),
        (["runs=0"], "runs"),
        (["runs=many"], "runs"),
        (["runs=auto", "estimator=[ekf]"], "runs"),
        (["runs=auto", "loop=truth"], "runs"),
        (["runs=auto", "output.saved_runs=60"], "output.saved_runs"),
    ],
)
def test_bad_values_are_refused_before_any_work(overrides, key):
    with pytest.raises(ConfigError) as err:
        validate(compose_config(overrides))
    assert err.value.key == key and "\n" not in str(err.value)
