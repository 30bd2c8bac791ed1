"""Tuning: the objective (quadest.evaluation.objective) on constructed summaries with a hand-computed value,
its one-line errors, and a real 4-trial Optuna search (conf/hparams_search/ut_optuna.yaml) whose
best value is the smallest objective recomputed from the trials' own summary.json files."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
import yaml
from omegaconf import OmegaConf

from quadest.app.cli import precheck
from quadest.evaluation.objective import objective_value

pytest.importorskip("hydra_plugins.hydra_optuna_sweeper", reason="needs the `tune` extra (in `test`)")

TUNED = {
    "estimator.srukf.alpha": (1e-3, 1.0),
    "estimator.srukf.beta": (0.0, 4.0),
    "estimator.srukf.kappa": (-3.0, 3.0),
    "model.process_noise.velocity": (1e-3, 0.1),
    "model.process_noise.angle": (1e-5, 1e-3),
    "model.process_noise.angle_rate": (1e-3, 0.1),
}


def _summary(rmse: list[float], nees_in_band: float | None, diverged: int = 0) -> dict:
    states = {f"s{i}": {"mean": v, "quantity": "filter"} for i, v in enumerate(rmse)}
    states["companion"] = {"mean": 1e6, "quantity": "companion"}  # must not count
    return {"estimators": {"f": {"rmse": states, "nees_in_band": nees_in_band, "diverged": diverged}}}


def test_objective_is_mean_log_rmse_plus_nees_penalty():
    objective = OmegaConf.create({"estimator": "f", "nees_penalty": 2.0})
    # ln of (1, e, e^2) averages to 1; 10 % of steps outside the band cost 2 x 0.1
    assert objective_value(objective, _summary([1.0, math.e, math.e**2], 0.9)) == pytest.approx(1.2, rel=1e-15)
    assert objective_value(objective, _summary([1.0, math.e, math.e**2], 0.9, diverged=1)) == math.inf
    assert objective_value(objective, _summary([1.0, None], None)) == math.inf


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("objective.estimator=ekf", "objective.estimator='ekf' is invalid: one of the selected estimators"),
        ("objective.nees_penalty=-1", "objective.nees_penalty=-1.0 is invalid: must be >= 0"),
        ("+objective.bogus=1", "objective.bogus=1 is invalid: not a key of ObjectiveConf"),
    ],
)
def test_bad_objective_fails_with_one_line(override, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        precheck(["estimator=[srukf]", "objective.estimator=srukf", override])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


@pytest.mark.slow
def test_four_optuna_trials_minimise_the_returned_objective(tmp_path):
    out = tmp_path / "search"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "quadest.app.cli",
            "hparams_search=ut_optuna",
            "runs=2",
            "duration=0.3",
            "hydra.sweeper.n_trials=4",
            "hydra.sweeper.sampler.n_startup_trials=2",
            f"hydra.sweep.dir={out}",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    trials = {}
    for job in range(4):
        summary = json.loads((out / str(job) / "summary.json").read_text())
        est = summary["estimators"]["srukf"]
        params = dict(o.split("=", 1) for o in summary["overrides"] if o.split("=", 1)[0] in TUNED)
        assert set(params) == set(TUNED)
        for key, value in params.items():
            low, high = TUNED[key]
            assert low <= float(value) <= high, (key, value)
        for key in ("alpha", "beta", "kappa"):  # the sampled values reach the filter
            assert est["parameters"][key] == pytest.approx(float(params[f"estimator.srukf.{key}"]), rel=1e-12)
        filter_rmse = [r["mean"] for r in est["rmse"].values() if r["quantity"] == "filter"]
        assert len(filter_rmse) == 6 and est["diverged"] == 0
        value = sum(math.log(v) for v in filter_rmse) / 6 + 1.0 * (1.0 - est["nees_in_band"])
        trials[job] = (value, params)
    best_job = min(trials, key=lambda j: trials[j][0])
    result = yaml.safe_load((out / "optimization_results.yaml").read_text())
    # the summary rounds nothing: the sweeper's best value is the recomputed one to round-off
    assert result["best_value"] == pytest.approx(trials[best_job][0], rel=1e-12)
    assert {k: float(v) for k, v in result["best_params"].items()} == pytest.approx(
        {k: float(v) for k, v in trials[best_job][1].items()}, rel=1e-12
    )
