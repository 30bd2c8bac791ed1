"""Cells of a UT sweep against the best cell of their panel: the paired interval equals scipy's
paired t interval, a shifted cell differs, a cell equal to the best up to round-off does not,
diverged runs leave the pair, and an estimator that ignores the swept parameters is left out."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from quadest.aggregate.versus_best import heat_maps, versus_best

PARAMS = ["sensor.error_scale", "sweep.alpha", "sweep.beta"]


def scores(cells: dict[tuple[float, float, float], np.ndarray], estimator: str = "srukf") -> pd.DataFrame:
    """A run_scores-like table: one row per cell × run, job numbers in dict order."""
    rows = []
    for job, ((scale, alpha, beta), values) in enumerate(cells.items()):
        for run, value in enumerate(values):
            rows.append({"estimator": estimator, "group": "velocities", "run": run, "score": value,
                         "diverged": False, "job": job, "sensor.error_scale": scale, "sweep.alpha": alpha,
                         "sweep.beta": beta})  # fmt: skip
    return pd.DataFrame(rows)


@pytest.fixture()
def base() -> np.ndarray:
    return 1.0 + 0.1 * np.random.default_rng(5).standard_normal(30)


def test_interval_is_the_paired_t_interval_and_a_shifted_cell_differs(base):
    noise = 0.02 * np.random.default_rng(6).standard_normal(30)
    table = versus_best(scores({(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base + 0.05 + noise}), PARAMS)
    row = table.set_index("job").loc[1]
    reference = stats.ttest_rel(base + 0.05 + noise, base).confidence_interval(0.95)
    assert row["best_job"] == 0
    assert row[["diff_ci_low", "diff_ci_high"]].tolist() == pytest.approx([reference.low, reference.high], rel=1e-12)
    assert row["differs"]
    assert not table.set_index("job").loc[0, "differs"]  # the best against itself: d = 0


def test_a_cell_that_is_no_different_does_not_differ(base):
    wobble = np.tile([0.01, -0.01], 15)  # mean exactly zero: the interval straddles zero
    table = versus_best(scores({(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base + wobble}), PARAMS)
    assert not table["differs"].any()


def test_round_off_differences_count_as_zero(base):
    """Equal filters differ systematically at round-off; a t interval would call that real."""
    table = versus_best(scores({(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base * (1 + 1e-9)}), PARAMS)
    assert not table["differs"].any()
    assert table["diff_mean"].tolist() == [0.0, 0.0]


def test_panels_are_compared_only_within_themselves(base):
    """A cell of another sensor level has other data: it is never some other panel's best."""
    cells = {(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base + 0.1, (3.0, 1.0, 2.0): base + 1.0,
             (3.0, 0.1, 2.0): base + 0.9}  # fmt: skip
    table = versus_best(scores(cells), PARAMS).set_index("job")
    assert table.loc[[0, 1], "best_job"].tolist() == [0, 0]
    assert table.loc[[2, 3], "best_job"].tolist() == [3, 3]


def test_diverged_runs_leave_the_pair(base):
    frame = scores({(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base + 0.05})
    frame.loc[(frame["job"] == 1) & (frame["run"] < 4), "diverged"] = True
    table = versus_best(frame, PARAMS).set_index("job")
    assert table.loc[1, "runs"] == 26
    assert table.loc[0, "runs"] == 30  # the best against itself: no run of it diverged


def test_an_estimator_that_ignores_the_swept_parameters_is_left_out(base, tmp_path):
    frame = pd.concat([scores({(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base}, estimator="ekf"),
                       scores({(1.0, 1.0, 2.0): base, (1.0, 0.1, 2.0): base + 0.05})])  # fmt: skip
    table = versus_best(frame, PARAMS)
    assert set(table["estimator"]) == {"srukf"}
    made = heat_maps(table, PARAMS, tmp_path)
    assert [p.name for p in made] == ["versus_best_srukf_velocities.png"]
