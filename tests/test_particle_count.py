"""The RMSE-against-particle-count figure: series and drawn lines from a hand-made metrics table."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from scipy.stats import t as student_t

from quadest.aggregate.particle_count import (
    EFFICIENCY,
    FIGURE,
    NOISE_CHANGE,
    NOISE_TREND,
    SERIES,
    TIME_EFFICIENCY,
    efficiency_table,
    main,
    noise_change,
    particle_count_series,
    plot_particle_count,
    time_efficiency,
)

# per-run RMSE of states p and q; run 2 of pf_20 diverged (its huge RMSE must be left out)
RMSE = {
    "ekf": [(0.5, 1.5), (1.0, 2.0), (1.5, 2.5)],  # per-run means 1.0, 1.5, 2.0
    "pf_10": [(1.0, 3.0), (2.0, 4.0), (3.0, 5.0)],  # 2, 3, 4
    "pf_20": [(1.0, 1.0), (2.0, 2.0), (1e6, 1e6)],  # 1, 2 (run 2 diverged)
    "ekpf_10": [(0.0, 2.0), (2.0, 2.0), (1.0, 3.0)],  # 1, 2, 2
}
PARTICLES = {"ekf": np.nan, "pf_10": 10.0, "pf_20": 20.0, "ekpf_10": 10.0}
STEP_US = {"ekf": 5.0, "pf_10": 20.0, "pf_20": 40.0, "ekpf_10": 100.0}


def _metrics() -> pd.DataFrame:
    rows = []
    for est, runs in RMSE.items():
        for run, values in enumerate(runs):
            for state, rmse in zip("pq", values, strict=True):
                diverged = est == "pf_20" and run == 2
                rows.append(
                    dict(estimator=est, run=run, state=state, quantity="filter", rmse=rmse, diverged=diverged,
                         particles=PARTICLES[est], step_time_us=STEP_US[est])
                )  # fmt: skip
        rows.append(  # a companion quantity, not a filter state: ignored
            dict(estimator=est, run=0, state="c", quantity="companion", rmse=1e3, diverged=False,
                 particles=PARTICLES[est], step_time_us=STEP_US[est])
        )  # fmt: skip
    return pd.DataFrame(rows)


def _expected(per_run: list[float]) -> tuple[float, float, float]:
    """Mean and the 95 % Student-t interval of per-run values."""
    x = np.array(per_run)
    half = student_t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x))
    return x.mean(), x.mean() - half, x.mean() + half


EXPECTED = {"ekf": [1.0, 1.5, 2.0], "pf_10": [2.0, 3.0, 4.0], "pf_20": [1.0, 2.0], "ekpf_10": [1.0, 2.0, 2.0]}


def test_series_averages_states_per_run_then_runs_and_drops_diverged_runs():
    series = particle_count_series(_metrics()).set_index("estimator")
    assert list(series.index) == ["ekf", "ekpf_10", "pf_10", "pf_20"]  # by family, then particle count
    assert series["family"].to_dict() == {"ekf": "ekf", "ekpf_10": "ekpf", "pf_10": "pf", "pf_20": "pf"}
    for est, per_run in EXPECTED.items():
        mean, low, high = _expected(per_run)
        row = series.loc[est]
        assert row["runs"] == len(per_run)
        np.testing.assert_allclose([row["rmse_mean"], row["ci95_low"], row["ci95_high"]], [mean, low, high], rtol=1e-12)
        assert row["step_time_us"] == STEP_US[est]
    assert np.isnan(series.loc["ekf", "particles"]) and series.loc["pf_20", "particles"] == 20


def test_figure_draws_each_family_against_count_and_time_and_the_ekf_as_a_reference(tmp_path):
    path = tmp_path / "figures" / FIGURE
    fig = plot_particle_count(particle_count_series(_metrics()), path)
    by_count, by_time = fig.axes
    families = {bars.get_label(): bars.lines[0] for bars in by_count.containers}  # errorbar: (data line, ...)
    assert sorted(families) == ["ekpf", "pf"]
    pf_mean = [_expected(EXPECTED["pf_10"])[0], _expected(EXPECTED["pf_20"])[0]]
    np.testing.assert_array_equal(families["pf"].get_xdata(), [10, 20])
    np.testing.assert_allclose(families["pf"].get_ydata(), pf_mean, rtol=1e-12)
    (reference,) = [line for line in by_count.get_lines() if line.get_label() == "ekf"]
    np.testing.assert_allclose(reference.get_ydata(), [1.5, 1.5], rtol=1e-12)  # horizontal (axhline)
    np.testing.assert_array_equal(reference.get_xdata(), [0, 1])  # across the whole axis
    time_lines = [(list(bars.lines[0].get_xdata()), list(bars.lines[0].get_ydata())) for bars in by_time.containers]
    assert ([20.0, 40.0], pytest.approx(pf_mean, rel=1e-12)) in time_lines
    assert ([100.0], pytest.approx([_expected(EXPECTED["ekpf_10"])[0]], rel=1e-12)) in time_lines
    assert ([5.0], pytest.approx([1.5], rel=1e-12)) in time_lines  # the EKF: one point
    plt.close(fig)
    assert path.is_file() and path.stat().st_size > 0


def test_command_writes_figure_and_series_and_refuses_folders_without_particle_metrics(tmp_path, capsys):
    _metrics().to_csv(tmp_path / "metrics.csv", index=False)
    assert main([str(tmp_path)]) == 0
    assert (tmp_path / "figures" / FIGURE).is_file()
    written = pd.read_csv(tmp_path / SERIES)
    assert list(written["estimator"]) == ["ekf", "ekpf_10", "pf_10", "pf_20"]
    assert not (tmp_path / EFFICIENCY).exists()  # no ILOPF: nothing to compare
    assert main([str(tmp_path / "missing")]) == 2
    assert "metrics.csv does not exist" in capsys.readouterr().err
    no_particles = tmp_path / "kalman_only"
    no_particles.mkdir()
    _metrics().drop(columns="particles").to_csv(no_particles / "metrics.csv", index=False)
    assert main([str(no_particles)]) == 2
    assert "no particle filters" in capsys.readouterr().err


def _pair_metrics(ekpf: list[float], ilopf: list[float], t_ekpf: float, t_ilopf: float, diverged=(), **cols):
    """A job with ekpf_10 and ilopf_10, one state, the given per-run RMSEs and times per step."""
    rows = []
    for est, values, t in (("ekpf_10", ekpf, t_ekpf), ("ilopf_10", ilopf, t_ilopf)):
        for run, rmse in enumerate(values):
            rows.append(
                dict(estimator=est, run=run, state="p", quantity="filter", rmse=rmse,
                     diverged=(est, run) in diverged, particles=10.0, step_time_us=t, **cols)
            )  # fmt: skip
    return pd.DataFrame(rows)


def test_error_ratio_is_ekpf_over_ilopf_rmse_with_a_paired_interval_and_time_ratio_from_the_job():
    """A constant per-run ratio 1.25 gives an interval of zero width (every paired residual is 0),
    so the interval is paired; a run diverged in ILOPF leaves the pair (its huge RMSE would move the
    ratio far from 1.25); the time ratio is t_EKPF / t_ILOPF and the time-based ratio the product."""
    ekpf = [1.0, 2.0, 1.5, 3.0, 2.5]
    ilopf = [v / 1.25 for v in ekpf[:4]] + [1e6]
    table = efficiency_table(_pair_metrics(ekpf, ilopf, 100.0, 125.0, diverged={("ilopf_10", 4)}))
    (row,) = table.itertuples(index=False)
    assert (row.estimator, row.reference, row.particles, row.runs) == ("ilopf_10", "ekpf_10", 10, 4)
    np.testing.assert_allclose([row.error_ratio, row.error_ci_low, row.error_ci_high], 1.25, rtol=1e-12)
    assert row.time_ratio == 0.8 and row.time_efficiency_ratio == pytest.approx(1.0, rel=1e-12)


def test_error_ratio_interval_covers_the_ratio_of_means_and_is_reproducible():
    rng = np.random.default_rng(0)
    ekpf = rng.uniform(1.0, 2.0, 40)
    ilopf = ekpf * rng.uniform(0.7, 1.0, 40)
    metrics = _pair_metrics(list(ekpf), list(ilopf), 1.0, 1.0)
    (row,) = efficiency_table(metrics).itertuples(index=False)
    assert row.error_ratio == pytest.approx(ekpf.mean() / ilopf.mean(), rel=1e-12)
    assert row.error_ci_low < row.error_ratio < row.error_ci_high
    assert efficiency_table(metrics).equals(efficiency_table(metrics))


def test_noise_change_pairs_the_runs_of_the_smallest_and_largest_q():
    """Every run 0.1 worse at the larger Q: a difference of exactly 0.1 with an interval of zero
    width; unpaired, the spread of the runs (0.5 .. 2.5) would widen it."""
    low = [0.5, 1.0, 1.5, 2.0, 2.5]
    jobs = [
        (0.05, _pair_metrics(low, low, 1.0, 1.0), None),
        (0.2, _pair_metrics([v + 0.1 for v in low], low, 1.0, 1.0), None),
    ]
    table = noise_change(jobs).set_index("estimator")
    np.testing.assert_allclose(table.loc["ekpf_10", ["mean_diff", "ci_low", "ci_high"]], 0.1, rtol=1e-12)
    np.testing.assert_allclose(table.loc["ekpf_10", "rel_diff"], 0.1 / 1.5, rtol=1e-12)
    np.testing.assert_array_equal(table.loc["ilopf_10", ["mean_diff", "ci_low", "ci_high"]], 0.0)
    assert (table["Q_low"] == 0.05).all() and (table["Q_high"] == 0.2).all()


def test_time_efficiency_takes_the_timing_interval_over_fresh_jobs_only():
    """Time ratios 0.8, 0.9 and 1.0 from three computed jobs, a fourth job from the cache (its
    timing repeats an earlier job's, so it is left out): mean 0.9, Student-t interval at 97.5 %
    with 2 degrees of freedom; the time-based ratio is error ratio × time ratio, its interval the
    product of the two intervals."""
    ekpf = [1.0, 1.2, 1.1]
    ilopf = [v / 1.25 for v in ekpf]
    jobs = [
        (q, _pair_metrics(ekpf, ilopf, 100.0 * r, 100.0, from_cache=cached), None)
        for q, r, cached in ((0.05, 0.8, False), (0.1, 0.9, False), (0.2, 1.0, False), (0.4, 5.0, True))
    ]
    table = time_efficiency(jobs)
    assert len(table) == 4 and (table["timings"] == 3).all()
    half = student_t.ppf(1 - 0.025 / 2, 2) * 0.1 / np.sqrt(3)
    row = table.iloc[0]
    np.testing.assert_allclose([row.time_ratio, row.time_ci_low, row.time_ci_high], [0.9, 0.9 - half, 0.9 + half])
    np.testing.assert_allclose(row.time_efficiency_ratio, 1.25 * 0.9, rtol=1e-12)
    np.testing.assert_allclose(
        [row.time_efficiency_ci_low, row.time_efficiency_ci_high], [1.25 * (0.9 - half), 1.25 * (0.9 + half)]
    )


def test_sweep_command_writes_the_three_tables_and_refuses_a_folder_without_a_q_sweep(tmp_path, capsys):
    ekpf = [1.0, 2.0, 1.5]
    for job, q in enumerate((0.05, 0.2)):
        folder = tmp_path / str(job)
        folder.mkdir()
        _pair_metrics(ekpf, [v * (1 + q) for v in ekpf], 10.0, 12.0, from_cache=False).to_csv(folder / "metrics.csv")
        (folder / "config.yaml").write_text(f"seed: 5\nmodel:\n  Q: {q}\n")
        pd.DataFrame(
            {"estimator": ["ekpf_10", "ilopf_10"], "quantity": "filter", "mse_mean": [4.0, 9.0], "pcrlb": [1.0, 1.0]}
        ).to_csv(folder / "rmse_summary.csv", index=False)
    assert main(["--sweep", str(tmp_path)]) == 0
    trend = pd.read_csv(tmp_path / NOISE_TREND).set_index(["Q", "estimator"])
    assert trend.loc[(0.2, "ilopf_10"), "pooled_rmse"] == 3.0 and trend.loc[(0.2, "ilopf_10"), "pcrlb"] == 1.0
    assert (tmp_path / NOISE_CHANGE).is_file() and (tmp_path / TIME_EFFICIENCY).is_file()
    assert main(["--sweep", str(tmp_path / "0")]) == 2
    assert "no sweep over model.Q" in capsys.readouterr().err


def test_the_particle_count_callback_tabulates_the_run_and_a_sweep_over_q(tmp_path, capsys):
    """``experiment=seed001_rates`` and its Q sweep are one command each: the callback writes what
    ``python -m quadest.aggregate.particle_count`` writes (with ``--sweep`` for a multirun over
    two or more Q) and leaves another multirun alone."""
    from omegaconf import OmegaConf

    from quadest.app.callbacks import ParticleCountCallback

    ekpf = [1.0, 2.0, 1.5]
    job = tmp_path / "job"
    job.mkdir()
    _pair_metrics(ekpf, [v / 1.25 for v in ekpf], 100.0, 125.0).to_csv(job / "metrics.csv", index=False)
    ParticleCountCallback().on_run_end(OmegaConf.create({"hydra": {"runtime": {"output_dir": str(job)}}}))
    assert (job / EFFICIENCY).is_file()
    sweep = tmp_path / "sweep"
    for number, q in enumerate((0.05, 0.2)):
        folder = sweep / str(number)
        folder.mkdir(parents=True)
        _pair_metrics(ekpf, [v * (1 + q) for v in ekpf], 10.0, 12.0, from_cache=False).to_csv(folder / "metrics.csv")
        (folder / "config.yaml").write_text(f"seed: 5\nmodel:\n  Q: {q}\n")
        pd.DataFrame(
            {"estimator": ["ekpf_10", "ilopf_10"], "quantity": "filter", "mse_mean": [4.0, 9.0], "pcrlb": [1.0, 1.0]}
        ).to_csv(folder / "rmse_summary.csv", index=False)
    ParticleCountCallback().on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}}))
    assert (sweep / NOISE_TREND).is_file() and (sweep / TIME_EFFICIENCY).is_file()
    ParticleCountCallback().on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep / "0")}}}))
    assert "not a sweep over model.Q" in capsys.readouterr().out
