"""The compact aggregate of a large grid (``hydra.callbacks.aggregate.output: compact``): on a tiny
UT grid it writes exactly its files, its one-row-per-cell table agrees with the full aggregate of
the same sweep, and a bad value of the key ends the command before any job runs."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra.utils import instantiate

from quadest.aggregate.cli import main as aggregate_main
from quadest.aggregate.compact import cell_table, group_means
from quadest.aggregate.versus_best import versus_best
from test_sweeps import compose_experiment
from test_versus_best import PARAMS, scores

TINY = """
defaults:
  - config
  - override /estimator: [ekf, srukf]
  - override hydra/launcher: quadest_joblib
  - _self_
runs: 3
duration: 0.3
workers: 1
progress: false
output: {saved_runs: 0, figures: false}
cache: {enabled: false}
sweep: {alpha: 0.5, beta: 2.0, kappa: 0.0}
estimator:
  srukf: {alpha: "${sweep.alpha}", beta: "${sweep.beta}", kappa: "${sweep.kappa}"}
hydra:
  mode: MULTIRUN
  sweep: {subdir: "${hydra.job.num}"}
  sweeper:
    params:
      sensor.error_scale: 1.0,3.0
      sweep.alpha: 1e-3,1.0
      sweep.beta: 0.0,2.0
  callbacks:
    aggregate: {_target_: quadest.app.callbacks.AggregateCallback, output: compact}
"""
SWEPT = ["sensor.error_scale", "sweep.alpha", "sweep.beta"]


def quadest(tmp: Path, out: Path, *overrides: str) -> subprocess.CompletedProcess:
    """``quadest -cd tmp -cn tiny hydra.sweep.dir=out ...`` with one job at a time."""
    (tmp / "tiny.yaml").write_text(TINY)
    command = [sys.executable, "-m", "quadest.app.cli"]
    argv = [*command, "-cd", str(tmp), "-cn", "tiny", f"hydra.sweep.dir={out}", *overrides]
    env = {**os.environ, "QUADEST_WORKERS": "1"}
    return subprocess.run(argv, cwd=tmp, capture_output=True, text=True, timeout=600, env=env)


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory) -> dict[str, Path]:
    """The tiny grid run once with the compact aggregate, and a copy of its job folders aggregated
    in full by ``quadest-aggregate --output full``."""
    tmp = tmp_path_factory.mktemp("compact")
    proc = quadest(tmp, tmp / "compact")
    assert proc.returncode == 0, proc.stderr[-3000:]
    full = tmp / "full"
    shutil.copytree(tmp / "compact", full, ignore=shutil.ignore_patterns("aggregate"))
    assert aggregate_main([str(full), "--output", "full"]) == 0
    return {"compact": tmp / "compact" / "aggregate", "full": full / "aggregate"}


def files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


@pytest.mark.slow
def test_compact_output_writes_exactly_the_compact_files(sweeps):
    groups = pd.read_csv(sweeps["full"] / "versus_best.csv")["group"].unique()
    figures = {f"figures/versus_best_srukf_{g.replace(' ', '_')}.png" for g in groups}
    figures |= {"figures/cost_accuracy.png", "figures/cost_accuracy.pdf"}  # in every sweep's report
    tables = {
        f"{name}.{ext}" for name in ("versus_best_panels", "versus_best_counts", "timing") for ext in ("csv", "md")
    }
    assert files(sweeps["compact"]) == {"cells_compact.csv", "report.md", *tables, *figures}
    report = (sweeps["compact"] / "report.md").read_text()
    assert "](cells_compact.csv)" in report and "wall time of the sweep:" in report and "ok: 8" in report
    assert all(f"]({figure})" in report for figure in figures if figure.endswith(".png"))
    assert "Wall time of the sweep: " in (sweeps["compact"] / "timing.md").read_text()


@pytest.mark.slow
def test_the_cell_table_agrees_with_the_full_aggregate(sweeps):
    """One row per cell with the full aggregate's numbers: the versus-best columns of
    ``versus_best.csv``, the diverged runs of ``divergence.csv``, the same counts and timing, and
    the panels' best cells and the EKF's group RMSE (from ``cells.csv``: the mean of its states')."""
    compact = pd.read_csv(sweeps["compact"] / "cells_compact.csv").set_index("job")
    full = sweeps["full"]
    assert sorted(compact.index) == list(range(8)) and (compact["status"] == "ok").all()
    against_best = pd.read_csv(full / "versus_best.csv")
    assert set(against_best["estimator"]) == {"srukf"}  # the EKF does not take α, β, κ
    for row in against_best.to_dict("records"):
        cell = compact.loc[row["job"]]
        assert cell[SWEPT].tolist() == [row[key] for key in SWEPT]
        prefix = f"srukf.{row['group'].replace(' ', '_')}"
        got = cell[[f"{prefix}.{c}" for c in ("rmse_mean", "diff_mean", "diff_ci_low", "diff_ci_high")]]
        want = [row["score_mean"], row["diff_mean"], row["diff_ci_low"], row["diff_ci_high"]]
        np.testing.assert_allclose(got.to_numpy(float), want, rtol=1e-5, atol=1e-12)
        assert bool(cell[f"{prefix}.differs"]) == row["differs"]
    divergence = pd.read_csv(full / "divergence.csv")
    for row in divergence.itertuples(index=False):
        assert compact.loc[row.job, f"{row.estimator}.diverged"] == row.diverged
    for name in ("versus_best_counts", "timing"):
        pd.testing.assert_frame_equal(pd.read_csv(sweeps["compact"] / f"{name}.csv"), pd.read_csv(full / f"{name}.csv"))
    panels = pd.read_csv(sweeps["compact"] / "versus_best_panels.csv")
    assert len(panels) == 2 * against_best["group"].nunique()
    cells = pd.read_csv(full / "cells.csv")
    ekf = cells[(cells["estimator"] == "ekf") & (cells["quantity"] == "filter")]
    for row in panels.to_dict("records"):
        part = against_best[(against_best["group"] == row["group"])
                            & (against_best["sensor.error_scale"] == row["sensor.error_scale"])]  # fmt: skip
        assert row["best_job"] == part["best_job"].iloc[0]
        assert row["differ_from_best"] == part["differs"].sum() and row["cells"] == len(part)
        units = [u for u, g in {"m/s": "velocities", "rad/s": "angle rates", "rad": "angles", "m": "positions"}.items()
                 if g == row["group"]]  # fmt: skip
        states = ekf[ekf["unit"].isin(units) & ekf["job"].isin(part["job"])]
        expected = states.groupby("job")["rmse_mean"].mean().mean()
        assert row["ekf rmse_mean"] == pytest.approx(expected, rel=1e-5)


@pytest.mark.slow
def test_quadest_aggregate_keeps_the_sweeps_own_output(sweeps, tmp_path):
    """Without ``--output`` a re-aggregation writes what the sweep's ``multirun.yaml`` asks for."""
    again = tmp_path / "again"
    shutil.copytree(sweeps["full"].parent, again, ignore=shutil.ignore_patterns("aggregate"))
    assert aggregate_main([str(again)]) == 0
    assert files(again / "aggregate") == files(sweeps["compact"])


@pytest.mark.slow
def test_a_bad_output_fails_in_one_line_before_any_job(tmp_path):
    out = tmp_path / "never"
    proc = quadest(tmp_path, out, "hydra.callbacks.aggregate.output=tiny")
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "quadest: error: hydra.callbacks.aggregate.output='tiny' is invalid: one of full, compact "
        "(compact: one row per cell, for large grids; docs/experiments.md)"
    ]
    assert not out.exists()


def test_the_ut_grid_aggregates_compactly():
    cfg = compose_experiment("sweep_ut_grid", hydra=True)
    assert instantiate(cfg.hydra.callbacks.aggregate).output == "compact"


def test_each_row_is_its_own_cell():
    """A cell that differs is the row of its job, with its own swept values (a mislabelled row or a
    dropped flag shows here even when a tiny real sweep has no cell that differs)."""
    rng = np.random.default_rng(3)
    base = 1.0 + 0.1 * rng.standard_normal(30)
    frame = scores({(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base + 0.05, (3.0, 1.0, 2.0): base + 0.2,
                    (3.0, 0.1, 2.0): base + 0.2 + 0.01 * rng.standard_normal(30)})  # fmt: skip
    jobs = frame.drop_duplicates("job")[["job", *PARAMS]].assign(status="ok")
    table = cell_table(jobs, pd.DataFrame(), group_means(frame), versus_best(frame, PARAMS), PARAMS).set_index("job")
    assert table.loc[1, PARAMS].tolist() == [1.0, 0.1, 2.0]
    assert table["srukf.velocities.differs"].tolist() == [False, True, False, False]
    assert table.loc[1, "srukf.velocities.diff_mean"] == pytest.approx(0.05)
    assert table.loc[0, "srukf.velocities.rmse_mean"] == pytest.approx(base.mean())
