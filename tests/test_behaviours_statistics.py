"""Statistics behaviours a single-point bug breaks without any other test noticing.

- The "N of M states differ" count of the paired summary (the job's line and the sweep's
  ``paired_summary`` table) counts Holm-adjusted p-values (Holm 1979, here statsmodels'
  ``multipletests``), on tables where the raw p-values would give another count.
- A relative difference's bootstrap CI resamples numerator and denominator together: its ends
  equal the quantiles of an independent paired bootstrap of ``mean(d)/mean(ref)`` written here,
  within the Monte Carlo error of both (a distribution-free bound: the code's 2.5 % quantile of
  B₁ resamples sits at a uniform order statistic, so the test's own bootstrap distribution
  function evaluated there is 0.025 ± z·√(p(1−p)(1/B₁ + 1/B₂))).
- A ranking step's sign and verdict do not depend on the order in which the job lists the
  estimators.
- Every Student-t interval labelled 95 % covers the mean of a normal sample 95 % of the time:
  4000 samples of n = 3, coverage within 4.5 binomial standard deviations of 0.95 (±0.0155); a
  t quantile at 0.95, a normal quantile or the ddof=0 standard deviation give 0.90, 0.82, 0.93.
  The closed-loop control tables (``summarize_control`` and seed 003's paired rows) included.
- The paired comparison's percentile bootstrap CI, labelled 95 %, covers what a percentile
  bootstrap covers, P(|t_{n−1}| ≤ z √((n−1)/n)): 0.936 at 30 runs, 0.90 at 10, 0.85 at 5. That
  shortfall is the method's, not a planted bug; the test pins it so that a wrong tail or an
  unpaired resample still fails.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
from scipy import stats
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
    return paired_comparison(tidy({"ref": ref, "a": a, "b": b}, states), seed=1)


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


# --- relative differences: numerator and denominator resampled together ---


def independent_ratio_bootstrap(d: np.ndarray, ref: np.ndarray, resamples: int, seed: int) -> np.ndarray:
    """``mean(d*)/mean(ref*)`` over resamples of whole runs (indices drawn with replacement)."""
    idx = np.random.default_rng(seed).integers(0, d.size, (resamples, d.size))
    return d[idx].mean(axis=1) / ref[idx].mean(axis=1)


def assert_at_quantiles(low: float, high: float, reference: np.ndarray, code_resamples: int) -> None:
    """``low`` and ``high`` sit at the 2.5 % and 97.5 % points of the reference bootstrap."""
    p = 0.025
    tol = Z * np.sqrt(p * (1 - p) * (1.0 / code_resamples + 1.0 / reference.size))
    assert abs(np.mean(reference <= low) - p) <= tol, (np.mean(reference <= low), tol)
    assert abs(np.mean(reference >= high) - p) <= tol, (np.mean(reference >= high), tol)


def paired_ratio_problem():
    """Runs differing by a factor of ten, the estimator 5 % worse in each: paired resampling
    keeps the ratio near 0.05; resampling the reference apart would spread it by about ±30 %."""
    rng = np.random.default_rng(21)
    ref = rng.uniform(1.0, 10.0, 40)
    est = ref * (1.05 + rng.normal(0.0, 0.02, 40))
    return est, ref


def test_the_paired_comparisons_relative_ci_is_a_paired_bootstrap_of_the_ratio():
    from quadest.evaluation.paired import RESAMPLES

    est, ref = paired_ratio_problem()
    row = paired_comparison(tidy({"ref": ref[:, None], "est": est[:, None]}, ["x"]), seed=2).iloc[0]
    reference = independent_ratio_bootstrap(est - ref, ref, 40000, 3)
    assert_at_quantiles(row["rel_ci_low"], row["rel_ci_high"], reference, RESAMPLES)


def test_the_particle_count_intervals_are_paired_bootstraps_of_the_ratio():
    from quadest.aggregate.particle_count import RESAMPLES

    est, ref = paired_ratio_problem()
    reference = independent_ratio_bootstrap(est - ref, ref, 40000, 4)
    _, lo, hi, _, rlo, rhi = diff_interval(est, ref, np.random.default_rng(5), 0.95)
    assert_at_quantiles(rlo, rhi, reference, RESAMPLES)
    means = (est - ref)[np.random.default_rng(7).integers(0, est.size, (40000, est.size))].mean(axis=1)
    assert_at_quantiles(lo, hi, means, RESAMPLES)  # and the difference's own interval
    _, low, high = ratio_interval(est, ref, np.random.default_rng(6), 0.95)
    assert_at_quantiles(low - 1.0, high - 1.0, reference, RESAMPLES)  # est/ref − 1 = (est − ref)/ref


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


def percentile_bootstrap_coverage(n: int) -> float:
    """The coverage of a percentile bootstrap interval of a normal mean to first order: the
    bootstrap distribution of the mean is about N(x̄, s²(n−1)/n²), so the interval is
    x̄ ± z √((n−1)/n) s/√n and covers with probability P(|t_{n−1}| ≤ z √((n−1)/n))."""
    z = stats.norm.ppf(0.975)
    return float(2.0 * stats.t.cdf(z * np.sqrt((n - 1) / n), n - 1) - 1.0)


def test_the_paired_bootstrap_95_percent_interval_covers_as_a_percentile_bootstrap():
    """The paired comparison's bootstrap CI of a mean difference, on normal differences of
    n = 30 runs, 1000 samples (one per state of one table): its coverage is the percentile
    interval's, 0.936 at n = 30 (short of 95 % by the ratio of the ddof=0 to the ddof=1 standard
    deviation and the normal against the t quantile: 0.90 at n = 10, 0.85 at n = 5), within 4.5
    binomial standard deviations (±0.035). An unpaired resample covers nearly always, a 90 % tail
    about 0.88."""
    n, samples = 30, 1000
    expected = percentile_bootstrap_coverage(n)
    rng = np.random.default_rng(51)
    before = rng.uniform(1.0, 2.0, (samples, n))
    after = before + rng.normal(0.3, 0.2, (samples, n))
    table = paired_comparison(tidy({"ref": before.T, "est": after.T}, [f"s{j}" for j in range(samples)]), seed=52)
    coverage = np.mean((table["ci_low"] <= 0.3) & (0.3 <= table["ci_high"]))
    assert abs(coverage - expected) <= Z * np.sqrt(expected * (1 - expected) / samples), (coverage, expected)
