"""The paired comparison of one estimator across two jobs (``python -m quadest.aggregate.cross_job``)
on hand-made jobs whose answers are known: a job whose every per-run RMSE is a constant multiple
of the reference's gives that ratio with an interval of zero width; jobs on different seeds or run
counts are refused before anything is written; runs are paired by their index, whatever their
order in the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from quadest.aggregate.cross_job import REPORT, TABLE, main

RUNS = 12
STATES = ("x", "y", "z", "vx", "vy", "vz", "error_angle")
EPS = np.finfo(float).eps


def _write_job(folder: Path, rmse: np.ndarray, seed: int = 7, runs: int = RUNS, estimator: str = "mekf") -> Path:
    """A job folder whose ``metrics.csv`` holds ``rmse`` (runs × states) for ``estimator``."""
    rows = [
        dict(estimator=estimator, run=run, state=state, unit="-", quantity="filter", rmse=rmse[run, j],
             diverged=bool(np.isnan(rmse[run, j])), seed=seed, runs=runs)
        for run in range(rmse.shape[0]) for j, state in enumerate(STATES)
    ]  # fmt: skip
    folder.mkdir(parents=True)
    pd.DataFrame(rows).to_csv(folder / "metrics.csv", index=False)
    return folder


def _reference_rmse(seed: int = 5) -> np.ndarray:
    return 1.0 + np.random.default_rng(seed).random((RUNS, len(STATES)))


def _compare(tmp_path: Path, reference: Path, job: Path, *extra: str) -> tuple[int, Path]:
    out = tmp_path / "out"
    argv = [str(reference), str(job), "--estimator", "mekf", "--labels", "8 beacons", "3 beacons", "--out", str(out)]
    return main([*argv, *extra]), out


def test_a_constant_ratio_gives_that_ratio_with_a_zero_width_interval(tmp_path):
    """Every per-run RMSE of the job 1.25 times the reference's: the relative difference is 0.25 in
    every state (the 3-D position and velocity too: the root of summed squares scales by 1.25) and
    Fieller's interval has zero width, since ``a_i − ρ b_i`` vanishes at ρ = 1.25 in every run. Its
    ends are the roots of a quadratic whose discriminant is zero in exact arithmetic and a few ulp
    of its terms in floating point, so they sit √ε-close to the ratio (tolerance 10 √ε). A run
    diverged in the job leaves the comparison (11 of 12 runs)."""
    reference = _reference_rmse()
    job = 1.25 * reference
    job[3, :] = np.nan
    code, out = _compare(tmp_path, _write_job(tmp_path / "a", reference), _write_job(tmp_path / "b", job))
    assert code == 0
    table = pd.read_csv(out / TABLE)
    assert set(table["state"]) == {*STATES, "position_3d", "velocity_3d"}
    assert (table["pair"] == "3 beacons - 8 beacons").all()
    assert (table["runs"] == RUNS - 1).all() and (table["excluded_runs"] == 1).all()
    np.testing.assert_allclose(table["rel_diff"], 0.25, rtol=0, atol=8 * EPS)
    for end in ("rel_ci_low", "rel_ci_high"):
        np.testing.assert_allclose(table[end], 0.25, rtol=0, atol=10 * np.sqrt(EPS))
    position = table.set_index("state").loc["position_3d"]
    used = np.delete(reference, 3, axis=0)
    expected = np.sqrt((used[:, :3] ** 2).sum(axis=1)).mean()
    assert position["reference_rmse_mean"] == pytest.approx(expected, rel=8 * EPS)
    assert "| position_3d | m | 11 |" in (out / REPORT).read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("job", "words"),
    [
        (dict(seed=8), "seeds differ"),
        (dict(runs=RUNS + 1), "run counts differ"),
        (dict(estimator="hf"), "--estimator 'mekf' is not in"),
    ],
)
def test_jobs_that_do_not_share_their_runs_are_refused_before_any_work(tmp_path, capsys, job, words):
    """Run i of two jobs shares its draws only on the same seed and runs; a job without the
    estimator has nothing to compare. One line on stderr, exit status 2, nothing written."""
    reference = _write_job(tmp_path / "a", _reference_rmse())
    code, out = _compare(tmp_path, reference, _write_job(tmp_path / "b", _reference_rmse(6), **job))
    err = capsys.readouterr().err
    assert code == 2 and words in err and err.count("\n") == 1
    assert not out.exists()


def test_runs_are_paired_by_their_index_not_by_their_order_in_the_file(tmp_path):
    """The same job written with its rows shuffled gives the same table, value for value: run i is
    paired with run i, not with the i-th row of the other file. The per-run ratio varies (a second
    draw), so a mispaired table would differ."""
    reference = _write_job(tmp_path / "a", _reference_rmse())
    job = _write_job(tmp_path / "b", _reference_rmse(6))
    shuffled = tmp_path / "c"
    shuffled.mkdir()
    rows = pd.read_csv(job / "metrics.csv")
    rows.sample(frac=1.0, random_state=1).to_csv(shuffled / "metrics.csv", index=False)
    tables = []
    for name, folder in (("in order", job), ("shuffled", shuffled)):
        code, out = _compare(tmp_path / name, reference, folder)
        assert code == 0
        tables.append(pd.read_csv(out / TABLE).sort_values("state", ignore_index=True))
    pd.testing.assert_frame_equal(tables[0], tables[1], check_exact=True)
