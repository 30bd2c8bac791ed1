"""Seed 004's ranking table (``python -m quadest.aggregate.ranking``) on a hand-made metrics table
whose answers are known: the 3-D RMSE is the root of the summed squares of the axes, a step with
a large consistent difference holds (or is reversed), a step with no difference is not shown."""

from __future__ import annotations

import numpy as np
import pandas as pd

from quadest.aggregate.ranking import grouped_metrics, main, ranking_lines

RUNS = 30
STATES = ("x", "y", "z", "vx", "vy", "vz", "error_angle")


def _metrics() -> pd.DataFrame:
    """hhcf 10 % better than hf everywhere; hckf 10 % worse than mekf (the seed's step reversed);
    hf and hckf equal but for a sign-alternating wobble of ±1 % (no consistent difference)."""
    base = 1.0 + 0.1 * np.random.default_rng(3).random(RUNS)
    wobble = np.where(np.arange(RUNS) % 2 == 0, 1.01, 0.99)
    scale = {"mekf": base, "hckf": 1.1 * base, "hf": 1.1 * base * wobble, "hhcf": 0.99 * base * wobble}
    rows = [
        dict(estimator=est, run=run, state=state, unit="-", quantity="filter", rmse=s[run] * (1 + i), diverged=False,
             seed=7)
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
    assert (tmp_path / "ranking.md").read_text().splitlines() == lines
    assert main([str(tmp_path / "missing")]) == 2
