"""Seed 004's ranking table (``python -m quadest.aggregate.ranking``) on a hand-made metrics table
whose answers are known: the 3-D RMSE is the root of the summed squares of the axes, a step with
a large consistent difference holds (or is reversed), a step with no difference is not shown; the
step-time ratio's geometric mean and Student-t interval over jobs, by hand."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from quadest.aggregate.ranking import grouped_metrics, grouped_paired, main, ranking_lines, step_time_ratios

RUNS = 30
STATES = ("x", "y", "z", "vx", "vy", "vz", "error_angle")
TIME = {"mekf": 40.0, "hckf": 1000.0, "hf": 60.0, "hhcf": 1100.0}


def _metrics() -> pd.DataFrame:
    """hhcf 10 % better than hf everywhere; hckf 10 % worse than mekf (the seed's step reversed);
    hf and hckf equal but for a sign-alternating wobble of ±1 % (no consistent difference)."""
    base = 1.0 + 0.1 * np.random.default_rng(3).random(RUNS)
    wobble = np.where(np.arange(RUNS) % 2 == 0, 1.01, 0.99)
    scale = {"mekf": base, "hckf": 1.1 * base, "hf": 1.1 * base * wobble, "hhcf": 0.99 * base * wobble}
    rows = [
        dict(estimator=est, run=run, state=state, unit="-", quantity="filter", rmse=s[run] * (1 + i), diverged=False,
             seed=7, step_time_us=TIME[est])
        for est, s in scale.items() for run in range(RUNS) for i, state in enumerate(STATES)
    ]  # fmt: skip
    return pd.DataFrame(rows)


def test_grouped_rmse_is_the_root_of_the_summed_axis_squares():
    g = grouped_metrics(_metrics())
    row = g[(g["estimator"] == "hf") & (g["run"] == 4)].set_index("state")["rmse"]
    s = 1.1 * (1.0 + 0.1 * np.random.default_rng(3).random(RUNS))[4] * 1.01
    assert np.isclose(row["position_3d"], s * np.sqrt(1 + 4 + 9), rtol=1e-14)
    assert np.isclose(row["velocity_3d"], s * np.sqrt(16 + 25 + 36), rtol=1e-14)
    assert np.isclose(row["error_angle"], 7 * s, rtol=1e-14)


def test_a_run_diverged_in_one_filter_leaves_only_the_pairs_it_diverged_in():
    """A diverged run has NaN RMSE in every state (metrics.csv); it must stay a row of the grouped
    table so that the pairs without that filter still count all runs (dropping it made the runs of
    two filters misalign, and the comparison failed)."""
    metrics = _metrics()
    gone = (metrics["estimator"] == "hckf") & (metrics["run"] == 5)
    metrics.loc[gone, "rmse"], metrics.loc[gone, "diverged"] = np.nan, True
    g = grouped_metrics(metrics)
    assert len(g) == 4 * RUNS * 3 and g.loc[(g["estimator"] == "hckf") & (g["run"] == 5), "diverged"].all()
    runs = grouped_paired(metrics).groupby("pair")["runs"].first()
    assert runs["hckf - mekf"] == RUNS - 1 and runs["hhcf - hf"] == RUNS


def test_verdicts_follow_the_sign_and_the_holm_corrected_test(tmp_path):
    lines = ranking_lines(_metrics())
    verdict = {tuple(c.strip() for c in line.split("|")[1:3]): line.split("|")[-2].strip() for line in lines[2:]}
    for state in ("position_3d", "velocity_3d", "error_angle"):
        assert verdict[("hhcf > hf", state)] == "yes"  # -10 % in every run
        assert verdict[("hckf > mekf", state)] == "no (reversed)"  # +10 % in every run
        assert verdict[("hf > hckf", state)] == "not shown"  # ±1 %, half the runs each way
    assert not any("srukf" in key[0] for key in verdict)  # steps whose filters are absent are left out
    _metrics().to_csv(tmp_path / "metrics.csv", index=False)
    assert main([str(tmp_path)]) == 0
    assert (tmp_path / "ranking.md").read_text().splitlines()[: len(lines)] == lines
    ratios = pd.read_csv(tmp_path / "step_time.csv").set_index("estimator")
    assert ratios.loc["hhcf", "ratio"] == 1.1 and ratios.loc["hhcf", "jobs"] == 1
    assert np.isnan(ratios.loc["hhcf", "rel_ci_low"])  # one job: no interval
    assert len(pd.read_csv(tmp_path / "paired_grouped.csv")) == 6 * 3  # 4 estimators: 6 pairs x 3 states
    assert main([str(tmp_path / "missing")]) == 2


def test_step_time_ratio_is_the_geometric_mean_with_a_t_interval_over_jobs():
    """Ratios 1.0, 1.1, 1.3 over three jobs: geometric mean (1.43)^(1/3) and the 95 % t interval
    of the mean log ratio (2 degrees of freedom); a pair with a missing estimator is left out."""
    ratios = np.array([1.0, 1.1, 1.3])
    times = pd.DataFrame(
        [{"job": j, "estimator": "hckf", "step_time_us": 200.0 * (j + 1)} for j in range(3)]
        + [{"job": j, "estimator": "hhcf", "step_time_us": 200.0 * (j + 1) * r} for j, r in enumerate(ratios)]
    )
    row = step_time_ratios(times).set_index("estimator").loc["hhcf"]
    logs = np.log(ratios)
    half = stats.t.ppf(0.975, 2) * logs.std(ddof=1) / np.sqrt(3)
    assert row["jobs"] == 3 and np.isclose(row["ratio"], 1.43 ** (1 / 3), rtol=1e-14)
    np.testing.assert_allclose([row["ratio_ci_low"], row["ratio_ci_high"]], np.exp(logs.mean() + [-half, half]))
    np.testing.assert_allclose(row["rel_diff"], row["ratio"] - 1.0, rtol=0, atol=1e-15)
    assert list(step_time_ratios(times)["estimator"]) == ["hhcf"]


def test_the_ranking_callback_tabulates_the_run_and_the_sweep_when_they_end(tmp_path, capsys):
    """``experiment=seed004_landing`` (and the sweeps over it) is one command: its callback writes
    what ``python -m quadest.aggregate.ranking`` writes, for a finished run, and skips a failed one."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from omegaconf import OmegaConf

    from quadest.app.callbacks import RankingCallback
    from quadest.app.schema import register_schemas
    from quadest.config.paths import config_dir

    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=seed004_landing"], return_hydra_config=True)
    GlobalHydra.instance().clear()
    callbacks = cfg.hydra.callbacks
    assert callbacks.ranking._target_ == "quadest.app.callbacks.RankingCallback"
    job = tmp_path / "job"
    job.mkdir()
    _metrics().to_csv(job / "metrics.csv", index=False)
    RankingCallback().on_run_end(OmegaConf.create({"hydra": {"runtime": {"output_dir": str(job)}}}))
    assert (job / "ranking.md").read_text().splitlines()[:3] == ranking_lines(_metrics())[:3]
    failed = tmp_path / "failed"
    failed.mkdir()
    RankingCallback().on_run_end(OmegaConf.create({"hydra": {"runtime": {"output_dir": str(failed)}}}))
    assert "the job failed" in capsys.readouterr().out and not (failed / "ranking.md").exists()
