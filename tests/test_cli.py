"""The ``quadest`` command end to end, its bad-input errors, composition and reproducibility."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf

from helpers import compose_config
from quadest.app.job import run_job
from quadest.config.paths import config_dir

SMALL = ["runs=3", "duration=0.5", "progress=false"]


def quadest(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "HYDRA_FULL_ERROR": "0"}
    return subprocess.run(
        [sys.executable, "-m", "quadest.app.cli", *args], cwd=cwd, capture_output=True, text=True, timeout=300, env=env
    )


@pytest.mark.slow
def test_cli_runs_and_writes_documented_outputs(tmp_path):
    out = tmp_path / "run"
    proc = quadest([*SMALL, f"hydra.run.dir={out}"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "Per-state RMSE" in proc.stdout
    assert f"Outputs: {out}" in proc.stdout
    for name in (
        "metrics.csv",
        "rmse_summary.csv",
        "rmse_table.md",
        "summary.json",
        "config.yaml",
        "timeseries.npz",
        "figures/truth_vs_estimate.png",
        "figures/errors_3sigma.png",
        "paired_comparison.csv",
    ):
        assert (out / name).is_file(), name
    paired = pd.read_csv(out / "paired_comparison.csv")
    assert list(dict.fromkeys(paired["pair"])) == ["ukf - ekf", "srukf - ekf", "srukf - ukf"]
    assert len(paired) == 3 * (6 + 6)  # pairs × (filter states + companions)
    assert "## Paired differences" in (out / "rmse_table.md").read_text()
    for pair in ("ukf - ekf", "srukf - ekf", "srukf - ukf"):  # one printed line per pair
        assert sum(line.strip().startswith(f"{pair}: ") for line in proc.stdout.splitlines()) == 1, pair
    table = pd.read_csv(out / "metrics.csv")
    assert set(table["estimator"]) == {"ekf", "ukf", "srukf"}
    assert len(table) == 3 * 3 * (6 + 6)  # estimators × runs × (filter states + companions)
    for col in (
        "run",
        "state",
        "rmse",
        "diverged",
        "mean_nees",
        "mean_nis",
        "step_time_us",
        "alpha",
        "beta",
        "kappa",
        "sensor",
        "error_scale",
        "scenario",
        "formulation",
        "calibrated",
        "seed",
    ):
        assert col in table.columns, col
    summary = json.loads((out / "summary.json").read_text())
    assert summary["schema_version"] == 1 and summary["status"] == "ok"
    assert set(summary["estimators"]) == {"ekf", "ukf", "srukf"}
    assert summary["estimators"]["srukf"]["parameters"]["alpha"] == 0.5


@pytest.mark.slow
def test_cli_works_from_any_directory(tmp_path):
    """The config tree is found by absolute path, not relative to the working directory."""
    elsewhere = tmp_path / "somewhere" / "else"
    elsewhere.mkdir(parents=True)
    proc = quadest(
        ["runs=1", "duration=0.1", "progress=false", "output.figures=false", f"hydra.run.dir={tmp_path / 'o'}"],
        elsewhere,
    )
    assert proc.returncode == 0, proc.stderr


BAD_INPUT = [
    ("sensor=foo", "sensor", "consumer, ideal, tactical"),
    ("estimator=[srukf,nope]", "estimator", "srckf, srckf5, srukf, ukf"),
    ("estimator.srukf.alpa=1", "estimator.srukf.alpa", "alpha, beta, kappa"),
    ("estimator.srukf.alpha=abc", "estimator.srukf.alpha", "Float"),
    ("estimator.srukf.alpha=0", "estimator.srukf.alpha", "> 0"),
    ("estimator.ukf.alpha=-0.5", "estimator.ukf.alpha", "> 0"),
    ("estimator.srukf.kappa=-6", "estimator.srukf.kappa", "kappa > -6"),
    ("model.process_noise.velocity=-1", "model.process_noise.velocity", "> 0"),
    ("model.initial_std.angle_rate=0", "model.initial_std.angle_rate", "> 0"),
    ("sensor.gyro.white_noise=-1e-4", "sensor.gyro.white_noise", ">= 0"),
    ("sensor.accel.bias=-1", "sensor.accel.bias", ">= 0"),
    ("sample_period=0", "sample_period", "> 0"),
    ("sample_period=-0.01", "sample_period", "> 0"),
    ("duration=0.001", "duration", "at least one sample period"),
    ("runs=0", "runs", ">= 1"),
    ("model.formulation=quaternion", "model.formulation", "thesis"),
    ("+bogus_key=1", "bogus_key", "not a key of ExperimentConf; allowed"),  # "+" adds keys past struct mode
    ("+sensor.gyro.bogus=2", "sensor.gyro.bogus", "white_noise"),
]


@pytest.mark.parametrize(("override", "key", "allowed"), BAD_INPUT)
@pytest.mark.slow
def test_bad_input_gives_one_line_naming_the_key(tmp_path, override, key, allowed):
    proc = quadest([override, f"hydra.run.dir={tmp_path / 'o'}"], tmp_path)
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("quadest: error:")
    assert key in lines[0] and allowed in lines[0]
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()  # nothing ran


GROUPS = {
    g: sorted(p.stem for p in (Path(config_dir()) / g).glob("*.yaml"))
    for g in ("model", "sensor", "scenario", "estimator")
}


@pytest.mark.parametrize(
    ("model", "sensor", "scenario"), list(itertools.product(GROUPS["model"], GROUPS["sensor"], GROUPS["scenario"]))
)
@pytest.mark.slow
def test_every_group_option_composes_and_validates(model, sensor, scenario):
    """Every option's defaults validate on every model, except where the model's dimension rules
    an option out: ``ghkf``'s default grid of 3^n points is refused above the rule's maximum."""
    from quadest.app.settings import data_settings
    from quadest.app.validate import validate
    from quadest.errors import ConfigError
    from quadest.numerics.rules import GaussHermiteRule
    from quadest.simulation.registry import state_dimension

    def composed(estimators: list[str]):
        return compose_config(
            [f"model={model}", f"sensor={sensor}", f"scenario={scenario}", f"estimator=[{','.join(estimators)}]"]
        )

    cfg = composed(GROUPS["estimator"])
    assert set(cfg.estimator) == set(GROUPS["estimator"])
    if GaussHermiteRule(3).size_problem(state_dimension(data_settings(cfg))) is None:
        validate(cfg)
        return
    with pytest.raises(ConfigError, match=r"estimator\.ghkf\.p"):
        validate(cfg)
    validate(composed([name for name in GROUPS["estimator"] if name != "ghkf"]))


def small_job(tmp_path: Path, name: str, extra: list[str]) -> pd.DataFrame:
    cfg = compose_config([*SMALL, "output.figures=false", *extra])
    run_job(cfg, tmp_path / name)
    return pd.read_csv(tmp_path / name / "metrics.csv")


@pytest.mark.slow
def test_same_config_and_seed_give_identical_numbers(tmp_path):
    a = small_job(tmp_path, "a", ["workers=1"])
    b = small_job(tmp_path, "b", ["workers=2", "cache.enabled=false"])  # computed, not a's cached results
    cols = ["rmse", "mean_nees", "mean_nis"]
    pd.testing.assert_frame_equal(a[cols], b[cols])
    c = small_job(tmp_path, "c", ["seed=99", "workers=1"])
    assert not np.allclose(a["rmse"], c["rmse"])


@pytest.mark.slow
def test_all_estimators_see_the_same_draws(tmp_path):
    """Common random numbers: identical estimators configured twice give identical metrics."""
    table = small_job(tmp_path, "crn", ["estimator=[srukf]", "+estimator@estimator.twin=srukf"])
    a = table[table["estimator"] == "srukf"]["rmse"].to_numpy()
    b = table[table["estimator"] == "twin"]["rmse"].to_numpy()
    np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_failing_estimator_is_recorded_not_fatal(tmp_path):
    """An SR-UKF with an indefinite UT (augmented, α = 1, β = 0, κ = 3 − n, so W0(c) = −2) fails
    in run 0 of this seed; the job finishes, the other runs count, and the table reports the
    diverged run with its reason."""
    table = small_job(
        tmp_path,
        "fail",
        [
            "model.formulation=augmented",
            "runs=4",
            "estimator=[srukf,ekf]",
            "model.initial_std.correlation=0.3",
            "estimator.srukf.alpha=1.0",
            "estimator.srukf.beta=0.0",
            "estimator.srukf.kappa=-6.0",
        ],
    )
    sr = table[(table["estimator"] == "srukf") & (table["state"] == "vx")]
    assert sr["diverged"].tolist() == [True, False, False, False]
    series = np.load(tmp_path / "fail" / "timeseries.npz")["srukf/estimate"]
    step = int(sr["diverged_step"].iloc[0])
    assert np.isnan(series[0, step:]).all() and np.isfinite(series[0, :step]).all()
    assert np.isfinite(series[1]).all()
    assert sr.loc[~sr["diverged"], "rmse"].notna().all()
    assert sr.loc[sr["diverged"], "failure_reason"].str.contains("indefinite").all()
    ekf = table[table["estimator"] == "ekf"]
    assert not ekf["diverged"].any()


@pytest.mark.parametrize("experiment", sorted(p.stem for p in (Path(config_dir()) / "experiment").glob("*.yaml")))
@pytest.mark.slow
def test_every_experiment_composes_and_validates(experiment):
    from quadest.app.validate import validate

    cfg = compose_config([f"experiment={experiment}"])
    validate(cfg)
    models, runs = _experiment_model_and_runs(experiment)
    assert cfg.model.name == models and cfg.runs == runs  # the file's settings reach the config


def _experiment_model_and_runs(experiment: str) -> tuple[str, int]:
    """The model and run count an experiment file sets, following the experiments it extends
    (a plain name in its defaults list, e.g. ``seed003_rates_only`` on ``seed003_closed_loop``)."""
    spec = OmegaConf.load(Path(config_dir()) / "experiment" / f"{experiment}.yaml")
    model, runs = None, None
    for entry in spec.defaults:
        if isinstance(entry, str) and entry != "_self_":
            model, runs = _experiment_model_and_runs(entry)
        elif "override /model" in entry:
            model = entry["override /model"]
    return model, spec.get("runs", runs)


def _reject_constant(name: str):
    raise ValueError(f"not strict JSON: {name}")


def test_summary_json_is_strict_json(tmp_path):
    """The validation models label their runs with NaN (no sensor error scale): summary.json must
    hold null there, which strict parsers (jq, JavaScript, ...) accept, and never NaN."""
    small_job(tmp_path, "linear", ["model=linear", "estimator=[ekf]"])
    summary = json.loads((tmp_path / "linear" / "summary.json").read_text(), parse_constant=_reject_constant)
    assert summary["labels"]["error_scale"] is None


def test_summary_json_names_the_code_that_made_it(tmp_path, monkeypatch):
    """A commit alone does not name the code when the tree held uncommitted changes: the summary
    says whether it did (``commit_dirty``) and carries the source digest (``code_version``), which
    names the code in any tree; outside git the commit is unknown and dirtiness ``None``."""
    from quadest.app import provenance as job
    from quadest.cache.keys import code_version

    small_job(tmp_path, "linear", ["model=linear", "estimator=[ekf]"])
    summary = json.loads((tmp_path / "linear" / "summary.json").read_text())
    assert summary["code_version"] == code_version() and summary["commit"] == job.provenance()["commit"]
    monkeypatch.setattr(job, "build_record", lambda: None)  # as a checkout: no record of a build
    answers = {"ls-files": "provenance.py", "rev-parse": "abc", "status": " M src/quadest/app/job.py"}
    monkeypatch.setattr(job, "_git", lambda *args: answers[args[0]])
    assert job.provenance()["commit_dirty"] is True
    answers["status"] = ""
    assert job.provenance() == {"commit": "abc", "commit_dirty": False, "commit_source": "git",
                                "code_version": code_version()}  # fmt: skip
    monkeypatch.setattr(job, "_git", lambda *args: None)
    assert job.provenance()["commit"] == "unknown" and job.provenance()["commit_dirty"] is None
