"""Paired statistics between estimators, on constructed tables with known answers and against scipy."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from quadest.evaluation.paired import holm, paired_comparison, paired_markdown, summary_lines

STATES = ("vx", "phi")


def metrics(rmse: dict[str, np.ndarray], diverged: dict[str, np.ndarray] | None = None) -> pd.DataFrame:
    """A tidy metrics table (the columns ``paired_comparison`` reads) from run × state arrays."""
    frames = []
    for name, values in rmse.items():
        runs = values.shape[0]
        flags = np.zeros(runs, dtype=bool) if diverged is None or name not in diverged else diverged[name]
        for j, state in enumerate(STATES):
            frames.append(
                pd.DataFrame(
                    {"estimator": name, "run": np.arange(runs), "state": state, "unit": "-", "quantity": "filter",
                     "rmse": values[:, j], "diverged": flags}
                )
            )  # fmt: skip
    return pd.concat(frames, ignore_index=True)


def rows(table: pd.DataFrame, pair: str) -> pd.DataFrame:
    return table[table["pair"] == pair].set_index("state")


def test_holm_matches_hand_computation():
    """m = 4: sorted 0.005, 0.01, 0.03, 0.04 → 4·0.005, 3·0.01, 2·0.03, max(1·0.04, 0.06); NaN
    is left out of m."""
    np.testing.assert_allclose(holm(np.array([0.01, 0.04, 0.03, 0.005])), [0.03, 0.06, 0.06, 0.02], rtol=1e-15)
    np.testing.assert_allclose(holm(np.array([0.02, np.nan, 0.5])), [0.04, np.nan, 0.5], rtol=1e-15)
    assert holm(np.array([0.6, 0.7])).tolist() == [1.0, 1.0]


def test_constant_shift_has_known_difference_ci_and_exact_p_values():
    """est = ref + 0.25 exactly (binary fractions): d̄ = 0.25 with a zero-width interval, the
    Wilcoxon signed-rank p-value with n = 8 equal positive differences is 2/2⁸ (all signs
    positive, two-sided), and the t statistic is infinite (p = 0)."""
    ref = 1.0 + np.arange(16).reshape(8, 2) / 8.0
    table = paired_comparison(metrics({"ref": ref, "est": ref + 0.25}))
    r = rows(table, "est - ref")
    assert (r["mean_diff"] == 0.25).all() and (r["ci_low"] == 0.25).all() and (r["ci_high"] == 0.25).all()
    np.testing.assert_allclose(r["rel_diff"], 0.25 / ref.mean(axis=0), rtol=1e-15)
    assert (r["p_wilcoxon"] == 2.0 / 2**8).all()
    assert (r["p_ttest"] == 0.0).all()
    assert (r["runs"] == 8).all() and (r["excluded_runs"] == 0).all()


def test_exact_small_sample_wilcoxon_p_value():
    """Differences 1..6, all positive: W⁺ = 21 is the largest of 2⁶ equally likely sign patterns,
    so the exact two-sided p-value is 2/64."""
    ref = np.full((6, 2), 10.0)
    est = ref + np.arange(1.0, 7.0)[:, None]
    r = rows(paired_comparison(metrics({"ref": ref, "est": est})), "est - ref")
    assert (r["p_wilcoxon"] == 2.0 / 64).all()
    d = np.arange(1.0, 7.0)  # t = d̄ / (s/√n) by hand
    t = d.mean() / (d.std(ddof=1) / np.sqrt(6))
    np.testing.assert_allclose(r["p_ttest"], 2 * stats.t.sf(t, df=5), rtol=1e-12)


def test_identical_estimators_do_not_differ():
    ref = np.random.default_rng(0).uniform(1, 2, (10, 2))
    table = paired_comparison(metrics({"a": ref, "twin": ref.copy()}))
    assert (table["mean_diff"] == 0).all() and (table["ci_low"] == 0).all() and (table["ci_high"] == 0).all()
    assert (table["p_wilcoxon"] == 1).all() and (table["p_ttest"] == 1).all()
    assert summary_lines(table)[0].startswith("twin - a: 0 of 2 states differ")


def test_round_off_differences_count_as_zero():
    """Filters equal in exact arithmetic differ by ~1e-13 relative (~1e-7 at α = 1e-3), always
    with the same sign here: without the round-off floor the rank test would call that a
    difference. A difference of 1e-5 relative is beyond the floor and is counted."""
    ref = np.random.default_rng(1).uniform(1, 2, (30, 2))
    for rel in (1e-13, 5e-7):
        table = paired_comparison(metrics({"a": ref, "b": ref * (1 + rel)}))
        assert (table["p_wilcoxon"] == 1).all() and (table["mean_diff"] == 0).all()
    table = paired_comparison(metrics({"a": ref, "b": ref * (1 + 1e-5)}))
    assert (table["p_wilcoxon"] < 1e-5).all()


def test_p_values_orientation_and_holm_match_scipy():
    rng = np.random.default_rng(2)
    a = rng.uniform(1, 2, (15, 2))
    b = a + rng.normal(0.05, 0.1, (15, 2))
    c = a + rng.normal(-0.02, 0.1, (15, 2))
    table = paired_comparison(metrics({"a": a, "b": b, "c": c}))
    assert list(dict.fromkeys(table["pair"])) == ["b - a", "c - a", "c - b"]
    for pair, (est, ref) in {"b - a": (b, a), "c - a": (c, a), "c - b": (c, b)}.items():
        r = rows(table, pair)
        for j, state in enumerate(STATES):
            assert r.loc[state, "p_wilcoxon"] == pytest.approx(stats.wilcoxon(est[:, j], ref[:, j]).pvalue, rel=1e-12)
            assert r.loc[state, "p_ttest"] == pytest.approx(stats.ttest_rel(est[:, j], ref[:, j]).pvalue, rel=1e-12)
            assert r.loc[state, "mean_diff"] == pytest.approx(np.mean(est[:, j] - ref[:, j]), rel=1e-12)
    p = table["p_wilcoxon"].to_numpy()  # Holm over all 3 pairs × 2 states, by hand
    order = np.argsort(p)
    expected = np.empty(6)
    expected[order] = np.minimum(1, np.maximum.accumulate((6 - np.arange(6)) * p[order]))
    np.testing.assert_allclose(table["p_wilcoxon_holm"], expected, rtol=1e-15)


def test_diverged_runs_are_excluded_pairwise():
    """Run 2 diverged in b only: pairs with b use the other runs, exactly as if run 2 were absent;
    the pair c - a keeps all runs."""
    rng = np.random.default_rng(4)
    a, b, c = (rng.uniform(1, 2, (12, 2)) for _ in range(3))
    flags = np.zeros(12, dtype=bool)
    flags[2] = True
    b_bad = b.copy()
    b_bad[2] = 1e6  # what a diverged run looks like
    table = paired_comparison(metrics({"a": a, "b": b_bad, "c": c}, {"b": flags}))
    keep = ~flags
    reference = paired_comparison(metrics({"a": a[keep], "b": b[keep]}))
    cols = ["mean_diff", "p_wilcoxon", "p_ttest", "runs"]
    pd.testing.assert_frame_equal(rows(table, "b - a")[cols], rows(reference, "b - a")[cols])
    assert (rows(table, "b - a")["excluded_runs"] == 1).all()
    assert (rows(table, "c - a")["runs"] == 12).all() and (rows(table, "c - a")["excluded_runs"] == 0).all()
    assert "(1 excluded: diverged in either)" in summary_lines(table)[0]


def test_the_interval_is_paired_over_runs():
    """Runs differ a lot (RMSE 1..10) but the estimators differ by 0.01 ± 0.001 in every run: an
    interval over paired differences is about as wide as their spread; treating the two
    estimators' runs as independent samples would make it hundreds of times wider."""
    rng = np.random.default_rng(6)
    ref = rng.uniform(1, 10, (50, 2))
    est = ref + rng.normal(0.01, 0.001, (50, 2))
    r = rows(paired_comparison(metrics({"ref": ref, "est": est})), "est - ref")
    assert ((r["ci_high"] - r["ci_low"]) < 0.002).all()
    assert ((r["ci_low"] < r["mean_diff"]) & (r["mean_diff"] < r["ci_high"])).all()


def test_the_intervals_are_student_t_of_the_mean_and_fieller_of_the_ratio():
    """Written out here: the mean difference's interval is d̄ ± t₀.₉₇₅,ₙ₋₁ s_d/√n; each end ρ of
    the relative difference's interval is a ratio at which the paired t statistic of d − ρ R
    (scipy's one-sample t-test) sits exactly at ±t₀.₉₇₅,ₙ₋₁ (Fieller 1954: the ratios the test
    does not reject). A normal quantile, ddof=0 or unpaired residuals move both far beyond round-off."""
    rng = np.random.default_rng(8)
    ref = rng.uniform(5, 6, (12, 2))
    d = 0.3 * (ref - 5.5) + rng.normal(0.1, 0.2, (12, 2))  # correlated with the reference's RMSE
    est = ref + d
    r = rows(paired_comparison(metrics({"ref": ref, "est": est})), "est - ref")
    t = stats.t.ppf(0.975, 11)
    dd = est - ref
    half = t * dd.std(axis=0, ddof=1) / np.sqrt(12)
    np.testing.assert_allclose(r["ci_low"], dd.mean(axis=0) - half, rtol=1e-12)
    np.testing.assert_allclose(r["ci_high"], dd.mean(axis=0) + half, rtol=1e-12)
    for j, state in enumerate(STATES):
        low, high = r.loc[state, "rel_ci_low"], r.loc[state, "rel_ci_high"]
        assert low < dd[:, j].mean() / ref[:, j].mean() < high
        for end, sign in ((low, 1.0), (high, -1.0)):  # below the estimate the residuals' mean is > 0
            statistic = stats.ttest_1samp(dd[:, j] - end * ref[:, j], 0.0).statistic
            np.testing.assert_allclose(statistic, sign * t, rtol=1e-9)


def test_the_comparison_draws_nothing_and_does_not_depend_on_other_estimators():
    rng = np.random.default_rng(10)
    a, b, c = (rng.uniform(1, 2, (20, 2)) for _ in range(3))
    np.random.seed(0)
    before = np.random.get_state()[1].copy()
    first = paired_comparison(metrics({"a": a, "b": b}))
    assert np.array_equal(np.random.get_state()[1], before)
    with_c = paired_comparison(metrics({"c": c, "a": a, "b": b}))  # another estimator: the same b - a
    ci = ["ci_low", "ci_high", "rel_ci_low", "rel_ci_high"]
    pd.testing.assert_frame_equal(rows(with_c, "b - a")[ci], rows(first, "b - a")[ci])


def test_fewer_than_two_runs_are_not_tested():
    table = paired_comparison(metrics({"a": np.ones((1, 2)), "b": np.full((1, 2), 2.0)}))
    assert table["p_wilcoxon"].isna().all() and table["ci_low"].isna().all()
    assert (table["mean_diff"] == 1.0).all()
    assert summary_lines(table) == ["b - a: not tested, 1 runs"]
    every_run_diverged = {"b": np.ones(3, dtype=bool)}
    table = paired_comparison(metrics({"a": np.ones((3, 2)), "b": np.full((3, 2), np.nan)}, every_run_diverged))
    assert table["mean_diff"].isna().all() and (table["runs"] == 0).all()
    assert summary_lines(table) == ["b - a: not tested, 0 runs (3 excluded: diverged in either)"]


def test_single_estimator_gives_an_empty_table():
    table = paired_comparison(metrics({"a": np.ones((5, 2))}))
    assert table.empty and summary_lines(table) == []


def test_an_unbounded_fieller_interval_prints_as_unbounded():
    """Three runs whose reference RMSE scatters around a small mean (its mean not significantly
    above 0 at t₀.₉₇₅,₂ = 4.3): Fieller's set has no ends, the CSV leaves them empty (NaN) and the
    printed line and the Markdown say "unbounded" rather than "[+nan, +nan]"."""
    ref = np.array([[0.1, 1.0], [2.0, 1.1], [0.2, 0.9]])
    table = paired_comparison(metrics({"ref": ref, "est": ref * np.array([[1.5, 1.2], [0.9, 1.1], [1.6, 1.3]])}))
    r = rows(table, "est - ref")
    assert np.isnan(r.loc["vx", "rel_ci_low"]) and np.isnan(r.loc["vx", "rel_ci_high"])
    assert np.isfinite(r.loc["phi", "rel_ci_low"])
    assert "[unbounded]" in paired_markdown(table) and "nan" not in paired_markdown(table).lower()
