"""Sweeps: experiments compose, a real multirun aggregates, launchers agree, and aggregation
survives failed, unfinished and missing jobs."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from quadest.aggregate import aggregate
from quadest.aggregate import main as aggregate_main
from quadest.config.schema import register_schemas
from quadest.config.validate import validate

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"

MINI = """
defaults:
  - config
  - override /estimator: [ukf, srukf]
  - override hydra/launcher: quadest_joblib
  - _self_
runs: 2
duration: 0.3
workers: 1
progress: false
output: {saved_runs: 1, figures: false}
sweep: {alpha: 0.5, beta: 2.0, kappa: 0.0}
estimator:
  ukf: {alpha: "${sweep.alpha}", beta: "${sweep.beta}", kappa: "${sweep.kappa}"}
  srukf: {alpha: "${sweep.alpha}", beta: "${sweep.beta}", kappa: "${sweep.kappa}"}
hydra:
  mode: MULTIRUN
  sweep: {subdir: "${hydra.job.num}"}
  sweeper:
    params:
      sweep.alpha: 0.5,1.0
      sweep.beta: 0.0,2.0
  callbacks:
    aggregate: {_target_: quadest.aggregate.AggregateCallback}
"""


@pytest.mark.parametrize("name", sorted(p.stem for p in EXPERIMENTS.glob("*.yaml")))
def test_every_experiment_file_composes_and_validates(name):
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(EXPERIMENTS), version_base="1.3"):
        cfg = compose(config_name=name, return_hydra_config=True)
    GlobalHydra.instance().clear()
    validate(cfg)
    assert "multirun" in cfg.hydra.sweep.dir and name in cfg.hydra.sweep.dir


def run_sweep(tmp: Path, launcher: str) -> Path:
    (tmp / "mini.yaml").write_text(MINI)
    out = tmp / f"sweep_{launcher}"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "quadest.cli",
            "-cd",
            str(tmp),
            "-cn",
            "mini",
            f"hydra/launcher={launcher}",
            f"hydra.sweep.dir={out}",
            "runs=2",  # a command-line override named like a table column
        ],
        cwd=tmp,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Aggregated:" in proc.stdout
    return out


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("sweeps")
    return {launcher: run_sweep(tmp, launcher) for launcher in ("quadest_joblib", "basic")}


def test_multirun_aggregate_has_the_expected_rows_and_columns(sweeps):
    out = sweeps["quadest_joblib"] / "aggregate"
    cells = pd.read_csv(out / "cells.csv")
    assert sorted(cells["job"].unique()) == [0, 1, 2, 3]
    assert len(cells) == 4 * 2 * (6 + 6)  # jobs × estimators × (filter states + companions)
    assert (cells["override.runs"] == 2).all() and (cells["runs"] == 2).all()
    for col in (
        "sweep.alpha",
        "sweep.beta",
        "estimator",
        "state",
        "rmse_mean",
        "rmse_std",
        "ci95_low",
        "ci95_high",
        "mse_mean",
        "diverged",
        "step_time_us",
        "pcrlb",
    ):
        assert col in cells.columns, col
    assert set(zip(cells["sweep.alpha"], cells["sweep.beta"], strict=True)) == {
        (0.5, 0.0),
        (0.5, 2.0),
        (1.0, 0.0),
        (1.0, 2.0),
    }
    for table in ("rmse", "best_cells", "divergence", "timing"):
        for ext in ("csv", "md", "tex"):
            assert (out / f"{table}.{ext}").is_file()
    assert len(pd.read_csv(out / "best_cells.csv")) == 2
    for fig in ("rmse_vs_alpha_srukf", "alpha_beta_heatmap_ukf", "rmse_bars"):
        assert (out / "figures" / f"{fig}.png").is_file() and (out / "figures" / f"{fig}.pdf").is_file()
    report = (out / "report.md").read_text()
    assert "commit:" in report and "ok: 4" in report


def test_basic_and_joblib_launchers_give_identical_metrics(sweeps):
    a = pd.read_csv(sweeps["quadest_joblib"] / "aggregate" / "cells.csv").sort_values(["job", "estimator", "state"])
    b = pd.read_csv(sweeps["basic"] / "aggregate" / "cells.csv").sort_values(["job", "estimator", "state"])
    cols = ["rmse_mean", "rmse_std", "mse_mean", "pooled_rmse", "mean_nees", "mean_nis"]
    pd.testing.assert_frame_equal(a[cols].reset_index(drop=True), b[cols].reset_index(drop=True))


def test_aggregation_reports_failed_unfinished_and_missing_jobs(sweeps, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(sweeps["basic"], broken)
    shutil.rmtree(broken / "aggregate")
    (broken / "1" / "summary.json").write_text(json.dumps({"status": "failed", "error": "ConfigError: boom"}))
    (broken / "2" / "summary.json").unlink()  # killed halfway
    shutil.rmtree(broken / "3")  # never ran
    report = aggregate(broken).read_text()
    jobs = pd.read_csv(broken / "aggregate" / "jobs.csv")
    assert jobs["status"].tolist() == ["ok", "failed", "did not finish", "missing"]
    assert "ConfigError: boom" in report and "missing" in report and "did not finish" in report
    cells = pd.read_csv(broken / "aggregate" / "cells.csv")
    assert cells["job"].unique().tolist() == [0]
    assert (broken / "aggregate" / "rmse.md").is_file()


def test_aggregate_command_rejects_a_missing_folder(tmp_path, capsys):
    assert aggregate_main([str(tmp_path / "nope")]) == 2
    assert "is not a directory" in capsys.readouterr().err
