"""The RMSE-against-particle-count figure: series and drawn lines from a hand-made metrics table."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from scipy.stats import t as student_t

from quadest.aggregate.particle_count import FIGURE, SERIES, main, particle_count_series, plot_particle_count

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
    assert main([str(tmp_path / "missing")]) == 2
    assert "metrics.csv does not exist" in capsys.readouterr().err
    no_particles = tmp_path / "kalman_only"
    no_particles.mkdir()
    _metrics().drop(columns="particles").to_csv(no_particles / "metrics.csv", index=False)
    assert main([str(no_particles)]) == 2
    assert "no particle filters" in capsys.readouterr().err
