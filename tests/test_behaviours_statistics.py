"""Statistics behaviours a single-point bug breaks without any other test noticing.

- The "N of M states differ" count of the paired summary (the job's line and the sweep's
  ``paired_summary`` table) counts Holm-adjusted p-values (Holm 1979, here statsmodels'
  ``multipletests``), on tables where the raw p-values would give another count.
- A relative difference's interval pairs each run's numerator with its own denominator: on runs
  differing threefold in scale with the estimator 5 % worse in each, it covers the true ratio 95 %
  at 5 runs (2000 samples, ±0.022); an interval that drops their covariance, or pairs a run
  with another run's reference, covers nearly always.
- A ranking step's sign and verdict do not depend on the order in which the job lists the
  estimators.
- Every Student-t interval labelled 95 % covers the mean of a normal sample 95 % of the time:
  4000 samples of n = 3, coverage within 4.5 binomial standard deviations of 0.95 (±0.0155); a
  t quantile at 0.95, a normal quantile or the ddof=0 standard deviation give 0.90, 0.82, 0.93.
  The closed-loop control tables (``summarize_control`` and seed 003's paired rows) included.
- The paired comparison's intervals, labelled 95 %, cover 95 % at 5 runs and at 30 (a
  percentile bootstrap, which they replace, covered 0.85 at 5 runs).
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest
from statsmodels.stats.multitest import multipletests

from quadest.aggregate.particle_count import diff_interval, particle_count_series, ratio_interval
from quadest.aggregate.ranking import STEPS, TIME_PAIRS, ranking_lines, step_time_ratios
from quadest.aggregate.statistics import paired_summary, with_confidence_interval
from quadest.aggregate.versus_best import paired_interval
from quadest.closed_loop.control_metrics import mean_ci, summarize_control
from quadest.closed_loop.seed003_report import paired_rows
from quadest.evaluation.paired import paired_comparison, summary_lines

Z = 4.5  # Monte Carlo bounds at 4.5 standard deviations: about 7e-6 two-sided each


def tidy(rmse: dict[str, np.ndarray], states: list[str]) -> pd.DataFrame:
    """A job's tidy metrics table from run × state RMSE arrays."""
    frames = []
    for name, values in rmse.items():
        runs = values.shape[0]
        columns = {"estimator": name, "run": np.tile(np.arange(runs), len(states)), "state": np.repeat(states, runs),
                   "unit": "-", "quantity": "filter", "rmse": values.T.ravel(), "diverged": False}  # fmt: skip
        frames.append(pd.DataFrame(columns))
    return pd.concat(frames, ignore_index=True)


# --- Holm in the count of differing states ---


def holm_table() -> pd.DataFrame:
    """Three estimators over eight states, with differences sized so that several raw Wilcoxon
    p-values lie below 0.05 but above Holm's thresholds."""
    rng = np.random.default_rng(11)
    states = [f"s{j}" for j in range(8)]
    ref = rng.uniform(1.0, 2.0, (12, 8))
    shift = np.linspace(0.0, 0.12, 8)
    a = ref + shift + rng.normal(0.0, 0.12, (12, 8))
    b = ref - shift[::-1] + rng.normal(0.0, 0.12, (12, 8))
    return paired_comparison(tidy({"ref": ref, "a": a, "b": b}, states))


def test_the_count_of_differing_states_uses_holm_adjusted_p_values():
    table = holm_table()
    adjusted = multipletests(table["p_wilcoxon"], method="holm")[1]
    np.testing.assert_allclose(table["p_wilcoxon_holm"], adjusted, rtol=1e-12)
    significant = pd.Series(adjusted < 0.05, index=table.index).groupby(table["pair"], sort=False).sum()
    raw = (table["p_wilcoxon"] < 0.05).groupby(table["pair"], sort=False).sum()
    assert (significant != raw).any()  # the table tells the two counts apart
    lines = summary_lines(table)
    for pair, expected in significant.items():
        line = next(ln for ln in lines if ln.startswith(f"{pair}:"))
        count = re.search(r"(\d+) of (\d+) states", line)
        assert count is not None, line
        assert (int(count[1]), int(count[2])) == (int(expected), 8), line
    summary = paired_summary(table.assign(job=0), []).set_index("pair")["states differing"]
    for pair, expected in significant.items():
        assert summary[pair] == f"{int(expected)} of 8"


# --- relative differences: numerator and denominator paired ---

RATIO_SAMPLES, RATIO_RUNS = 2000, 5


def paired_ratio_samples(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(runs, samples) per-run RMSEs: runs differing by a factor of three, the estimator 5 %
    worse in each run (normal per-run factor 1.05 ± 0.005, independent of the run's scale), so
    the ratio of means ``E[est − ref] / E[ref]`` is exactly 0.05. Paired, Fieller's interval is
    about ±0.6 %; pairing each run with another run's reference widens it about fourfold and it
    covers 99.7 %."""
    rng = np.random.default_rng(seed)
    ref = rng.uniform(3.0, 10.0, (RATIO_RUNS, RATIO_SAMPLES))
    return ref * (1.05 + rng.normal(0.0, 0.005, ref.shape)), ref


def assert_covers(low: np.ndarray, high: np.ndarray, truth: float, level: float = 0.95) -> None:
    """Coverage within Z binomial standard deviations of ``level`` (±0.022 at 2000 samples)."""
    coverage = np.mean((low <= truth) & (truth <= high))
    assert abs(coverage - level) <= Z * np.sqrt(level * (1 - level) / low.size), (coverage, low.size)


@pytest.mark.slow
def test_the_paired_comparisons_relative_ci_pairs_each_runs_numerator_and_denominator():
    """The relative difference's 95 % interval covers the true ratio 0.05 at 5 runs."""
    est, ref = paired_ratio_samples(21)
    states = [f"s{j}" for j in range(RATIO_SAMPLES)]
    table = paired_comparison(tidy({"ref": ref, "est": est}, states))
    assert_covers(table["rel_ci_low"].to_numpy(), table["rel_ci_high"].to_numpy(), 0.05)


def test_the_particle_count_intervals_pair_each_runs_numerator_and_denominator():
    """``diff_interval``'s relative interval covers 0.05 and ``ratio_interval`` of est/ref 1.05;
    on normal differences 0.3 ± 0.2, ``diff_interval``'s difference interval covers 0.3."""
    est, ref = paired_ratio_samples(22)
    out = np.array([diff_interval(est[:, j], ref[:, j], 0.95) for j in range(RATIO_SAMPLES)])
    assert_covers(out[:, 4], out[:, 5], 0.05)
    shifted = ref + np.random.default_rng(23).normal(0.3, 0.2, ref.shape)
    out = np.array([diff_interval(shifted[:, j], ref[:, j], 0.95) for j in range(RATIO_SAMPLES)])
    assert_covers(out[:, 1], out[:, 2], 0.3)
    ratios = np.array([ratio_interval(est[:, j], ref[:, j], 0.95) for j in range(RATIO_SAMPLES)])
    assert_covers(ratios[:, 1], ratios[:, 2], 1.05)


# --- a ranking step does not depend on the job's estimator order ---


def ranking_metrics(order: list[str]) -> pd.DataFrame:
    """Per-run RMSEs of seed 004's filters, each step's better filter clearly better, except
    ``ckf`` better than ``huber_ckf`` (a reversed step); listed in ``order``."""
    rng = np.random.default_rng(31)
    factor = {"hhcf": 0.7, "hf": 0.8, "hckf": 0.9, "mekf": 1.0, "huber_ckf": 1.1, "ckf": 0.95}
    states = ["x", "y", "z", "vx", "vy", "vz", "error_angle"]
    base = rng.uniform(1.0, 3.0, (20, len(states)))
    rmse = {name: base * factor[name] * (1.0 + rng.normal(0.0, 0.02, base.shape)) for name in factor}
    table = tidy({name: rmse[name] for name in order}, states)
    return table.assign(seed=7)


def ranking_rows(lines: list[str]) -> dict[tuple[str, str], tuple[float, str]]:
    """(claim, state) → (sign of the difference, verdict) of the ranking table's rows."""
    out = {}
    for line in lines[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        out[(cells[0], cells[1])] = (float(np.sign(float(cells[3].split()[0]))), cells[5])
    return out


def test_a_ranking_steps_sign_and_verdict_do_not_depend_on_the_estimator_order():
    names = ["hhcf", "hf", "hckf", "mekf", "huber_ckf", "ckf"]
    forward = ranking_rows(ranking_lines(ranking_metrics(names)))
    backward = ranking_rows(ranking_lines(ranking_metrics(names[::-1])))
    assert forward.keys() == backward.keys() and len(forward) == 3 * len(STEPS)
    for key, (sign, verdict) in forward.items():
        assert backward[key] == (sign, verdict), key
        reversed_step = key[0] == "huber_ckf > ckf"
        assert verdict == ("no (reversed)" if reversed_step else "yes"), key
        assert sign == (1.0 if reversed_step else -1.0), key


def test_a_ranking_rows_interval_is_ordered_and_holds_its_value_in_either_order():
    """A step whose better filter is listed later is the earlier one's difference with its sign
    flipped: the flipped interval's ends swap too. Fieller's interval holds its own ratio (the
    paired t statistic of ``a − r̂ b`` is 0 there), so ``low ≤ value ≤ high`` on every row."""
    names = ["hhcf", "hf", "hckf", "mekf", "huber_ckf", "ckf"]
    for order in (names, names[::-1]):
        for line in ranking_lines(ranking_metrics(order))[2:]:
            value, interval = [c.strip() for c in line.strip("|").split("|")][3].split(" % ")
            low, high = (float(x) for x in interval.strip("[]").split(","))
            assert low <= float(value) <= high, line


# --- coverage of every Student-t interval labelled 95 % ---

SAMPLES, N, MU = 4000, 3, 2.5


def normal_samples(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(MU, 0.7, (SAMPLES, N))


def assert_covers_95(low: np.ndarray, high: np.ndarray, truth: float) -> None:
    coverage = np.mean((low <= truth) & (truth <= high))
    assert abs(coverage - 0.95) <= Z * np.sqrt(0.95 * 0.05 / low.size), (coverage, low.size)


def test_the_aggregate_tables_95_percent_interval_covers_95_percent():
    x = normal_samples(41)
    cells = pd.DataFrame({"rmse_mean": x.mean(axis=1), "rmse_std": x.std(axis=1, ddof=1), "runs": N})
    out = with_confidence_interval(cells)
    assert_covers_95(out["ci95_low"].to_numpy(), out["ci95_high"].to_numpy(), MU)


def test_the_particle_count_series_95_percent_interval_covers_95_percent():
    x = normal_samples(42)
    est = np.repeat(np.arange(SAMPLES), N)
    metrics = pd.DataFrame({"estimator": [f"pf_{i}" for i in est], "run": np.tile(np.arange(N), SAMPLES),
                            "rmse": x.ravel(), "quantity": "filter", "diverged": False, "particles": 100.0,
                            "step_time_us": 1.0})  # fmt: skip
    out = particle_count_series(metrics)
    assert_covers_95(out["ci95_low"].to_numpy(), out["ci95_high"].to_numpy(), MU)


def test_the_closed_loop_control_tables_95_percent_intervals_cover_95_percent():
    """``mean_ci`` on 4000 samples; the two tables built on it on 1000 (±0.031: the pandas
    grouping costs more than the statistics; a quantile at 0.95 or a normal one still fails)."""
    x = normal_samples(43)
    intervals = np.array([mean_ci(row)[1:3] for row in x])
    assert_covers_95(intervals[:, 0], intervals[:, 1], MU)
    x, y, k = x[:1000], normal_samples(44)[:1000], 1000
    table = pd.DataFrame({"flight": np.repeat(np.arange(k), N), "metric": "overshoot_pct", "value": x.ravel()})
    out = summarize_control(table, ["flight"])
    assert_covers_95(out["ci_lo"].to_numpy(), out["ci_hi"].to_numpy(), MU)
    # seed 003's table: each arm's interval and the paired EKF in − EKF out interval
    metrics = [f"overshoot_pct[step {i}]" for i in range(k)]
    arms = {"estimate": x + y, "measured": y}  # ekf_in, ekf_out
    rows = pd.concat([pd.DataFrame({"metric": np.repeat(metrics, N), "run": np.tile(np.arange(N), k),
                                    "loop": loop, "value": v.ravel()}) for loop, v in arms.items()],
                     ignore_index=True)  # fmt: skip
    out = paired_rows(rows)
    for arm, truth in (("ekf_in", 2 * MU), ("ekf_out", MU), ("in_minus_out", MU)):
        part = out[out["arm"] == arm]
        assert len(part) == k
        assert_covers_95(part["ci_low"].to_numpy(), part["ci_high"].to_numpy(), truth)


@pytest.mark.slow
def test_the_paired_and_step_time_95_percent_intervals_cover_95_percent():
    """``paired_interval`` on 4000 samples; the step-time ratios on 300 jobs' worth of three
    independent pairs (900 samples, ±0.033)."""
    x = normal_samples(45)
    intervals = np.array([paired_interval(row)[1:] for row in x])
    assert_covers_95(intervals[:, 0], intervals[:, 1], MU)
    pairs = [("hhcf", "hckf"), ("huber_ckf", "ckf"), ("hf", "mekf")]
    assert set(pairs) <= set(TIME_PAIRS)
    names = [name for pair in pairs for name in pair]
    logs = np.random.default_rng(46).normal(0.3, 0.2, (300, len(pairs), N))
    low, high = [], []
    for sample in logs:
        times = np.ones((len(names), N))
        times[0::2] = np.exp(sample)
        frame = pd.DataFrame({"job": np.tile(np.arange(N), len(names)), "estimator": np.repeat(names, N),
                              "step_time_us": times.ravel()})  # fmt: skip
        ratios = step_time_ratios(frame).set_index(["estimator", "reference"])
        for est, ref in pairs:
            low.append(ratios.loc[(est, ref), "ratio_ci_low"])
            high.append(ratios.loc[(est, ref), "ratio_ci_high"])
    assert_covers_95(np.array(low), np.array(high), np.exp(0.3))


@pytest.mark.slow
def test_the_paired_comparisons_95_percent_intervals_cover_95_percent_at_few_runs():
    """The paired comparison's intervals of a mean difference, on normal differences of n = 5
    runs (the default comparison's count) and n = 30, 2000 samples each (one per state of one
    table), cover 95 % within 4.5 binomial standard deviations (±0.022). A percentile bootstrap
    covers 0.85 at 5 runs, a normal quantile 0.88, a 90 % tail 0.90."""
    for n in (5, 30):
        rng = np.random.default_rng(51 + n)
        before = rng.uniform(1.0, 2.0, (RATIO_SAMPLES, n))
        after = before + rng.normal(0.3, 0.2, (RATIO_SAMPLES, n))
        table = paired_comparison(tidy({"ref": before.T, "est": after.T}, [f"s{j}" for j in range(RATIO_SAMPLES)]))
        assert_covers(table["ci_low"].to_numpy(), table["ci_high"].to_numpy(), 0.3)
