"""Paired comparison of the estimators of one job: is a difference in RMSE real?

Every estimator of a job filters the same truth and measurements (common random numbers), so the
per-run RMSEs of two estimators are *paired* samples: run i of one and run i of the other differ
only by the estimator. For every pair (reference R, estimator E; R comes first in the job's
estimator order) and every state of the metrics table (filter states and companion values), with
``d_i = RMSE_E,i − RMSE_R,i`` over the runs that diverged in *neither* estimator (a run that
diverged in either is dropped from that pair only, so each pair uses its own runs):

- the mean difference ``d̄`` and the relative difference ``d̄ / mean(RMSE_R)`` (negative: E is
  more accurate), each with a 95 % interval over runs (:mod:`quadest.evaluation.intervals`):
  Student's t of the mean of the ``d_i``, and Fieller's interval of the ratio of means, the
  ratios ``ρ`` a paired t-test of ``d_i − ρ RMSE_R,i`` does not reject (NaN ends when the
  reference's mean is not significantly non-zero). Both are exact for normal per-run values at
  any run count, where a percentile bootstrap covers 85 % at 5 runs;
- the two-sided Wilcoxon signed-rank p-value (Wilcoxon 1945; ``scipy.stats.wilcoxon``, zero
  differences dropped, exact distribution for small samples) and the paired t-test p-value
  (``scipy.stats.ttest_1samp`` of the differences, which is ``scipy.stats.ttest_rel``);
- both p-values adjusted with Holm's step-down method (Holm 1979, *Scand. J. Statist.* 6, 65–70)
  over the whole family of pairs × states of the table.

Round-off: a per-run difference smaller than :data:`ROUND_OFF` times the reference's RMSE counts
as zero. Filters that are equal in exact arithmetic (the SR-UKF and filterpy's UKF with the same
α, β, κ) differ by about 1e-13 relative after a few thousand steps at α ≥ 0.1, systematically
enough for a rank test over 50 runs to call it significant. At α = 1e-3 the UT takes second
differences at ~1e-3 σ and the same two filters differ by up to ~1e-6 relative (measured on the
default quadrotor, ``sweep.alpha=0.001 sweep.kappa=-3``: 5.6e-7; ``docs/srukf.md``). 1e-6 is
above that and far below any difference between estimators that matters.

Degenerate samples: with every difference zero (an estimator against an identical
twin) both p-values are 1 and both intervals [0, 0]; with a constant non-zero difference the t statistic is infinite and
its p-value 0; with fewer than two usable runs the CI and p-values are NaN and left out of the
Holm family.
"""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pandas as pd
from scipy import stats

from quadest.evaluation.formatting import markdown_table
from quadest.evaluation.intervals import fieller_interval, mean_and_half_width

ROUND_OFF = 1e-6
SIGNIFICANCE = 0.05
CONFIDENCE = 0.95
MISS = 1.0 - CONFIDENCE

COLUMNS = (
    "pair", "estimator", "reference", "state", "unit", "quantity", "runs", "excluded_runs",
    "rmse_mean", "reference_rmse_mean", "mean_diff", "ci_low", "ci_high", "rel_diff", "rel_ci_low", "rel_ci_high",
    "p_wilcoxon", "p_ttest", "p_wilcoxon_holm", "p_ttest_holm",
)  # fmt: skip


def holm(p_values: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values (Holm 1979): with the m finite p-values sorted,
    ``p̃_(k) = max_{j ≤ k} min(1, (m − j + 1) p_(j))``. NaN entries stay NaN and do not count in m."""
    p = np.asarray(p_values, dtype=float)
    out = np.full(p.shape, np.nan)
    valid = np.flatnonzero(~np.isnan(p))
    order = valid[np.argsort(p[valid], kind="stable")]
    m = order.size
    out[order] = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    return out


def _p_values(d: np.ndarray) -> tuple[float, float]:
    """Two-sided Wilcoxon signed-rank and paired t p-values of the differences ``d``."""
    if d.size < 2:
        return np.nan, np.nan
    if not d.any():
        return 1.0, 1.0
    with warnings.catch_warnings():  # scipy warns about near-constant samples; the cases are handled above
        warnings.simplefilter("ignore", RuntimeWarning)
        return float(stats.wilcoxon(d).pvalue), float(stats.ttest_1samp(d, 0.0).pvalue)


def paired_runs(wide: dict[str, pd.DataFrame], name: str, ref_name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The per-run RMSEs (runs, states) of estimator ``name`` and of reference ``ref_name`` over
    the runs that diverged in neither, and the mask of those runs; ``wide`` as :func:`rmse_by_run`
    gives it."""
    est, ref = wide[name], wide[ref_name]
    states = [c for c in ref.columns if c != "diverged"]
    usable = ~(est["diverged"].to_numpy() | ref["diverged"].to_numpy())
    return est[states].to_numpy()[usable], ref[states].to_numpy()[usable], usable


def paired_differences(estimator: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``estimator − reference`` per run, zero where it is below :data:`ROUND_OFF` times the
    reference (module docstring: round-off)."""
    d = estimator - reference
    return np.where(np.abs(d) <= ROUND_OFF * np.abs(reference), 0.0, d)


def rmse_by_run(metrics: pd.DataFrame) -> tuple[list[str], pd.DataFrame, dict[str, pd.DataFrame]]:
    """The estimators of a tidy metrics table (in its order), its states (``state``, ``unit``,
    ``quantity``) and each estimator's run × state RMSE table with a ``diverged`` column."""
    names = list(dict.fromkeys(metrics["estimator"]))
    states = metrics.drop_duplicates("state")[["state", "unit", "quantity"]]
    wide = {}
    for name in names:
        sub = metrics[metrics["estimator"] == name]
        table = sub.pivot(index="run", columns="state", values="rmse")[list(states["state"])]
        table["diverged"] = sub.groupby("run")["diverged"].any().astype(bool)
        wide[name] = table
    return names, states, wide


def _compare(wide: dict[str, pd.DataFrame], name: str, ref_name: str) -> list[dict]:
    """Rows of the pair ``name - ref_name``, one per state; ``wide`` maps each estimator to its
    run × state RMSE table with a ``diverged`` column."""
    states = [c for c in wide[ref_name].columns if c != "diverged"]
    a, b, usable = paired_runs(wide, name, ref_name)
    d = paired_differences(a, b)
    n = d.shape[0]
    mean_d, mean_ref, mean_est = (v.mean(axis=0) if n else np.full(len(states), np.nan) for v in (d, b, a))
    with np.errstate(divide="ignore", invalid="ignore"):  # a reference RMSE of exactly 0
        rel = mean_d / mean_ref
    half_d = mean_and_half_width(d, MISS)[1]  # NaN below two runs
    _, rel_low, rel_high = fieller_interval(d, b, MISS)
    rows = []
    for j, state in enumerate(states):
        p_w, p_t = _p_values(d[:, j])
        rows.append(
            {
                "pair": f"{name} - {ref_name}", "estimator": name, "reference": ref_name, "state": state,
                "runs": n, "excluded_runs": int((~usable).sum()),
                "rmse_mean": mean_est[j], "reference_rmse_mean": mean_ref[j], "mean_diff": mean_d[j],
                "ci_low": mean_d[j] - half_d[j], "ci_high": mean_d[j] + half_d[j], "rel_diff": rel[j],
                "rel_ci_low": rel_low[j], "rel_ci_high": rel_high[j],
                "p_wilcoxon": p_w, "p_ttest": p_t,
            }
        )  # fmt: skip
    return rows


def paired_comparison(metrics: pd.DataFrame) -> pd.DataFrame:
    """The paired comparison of every pair of estimators in a job's tidy metrics table.

    Args:
        metrics: the job's ``metrics.csv`` table (columns ``estimator``, ``run``, ``state``,
            ``unit``, ``quantity``, ``rmse``, ``diverged``), estimators in the job's order.

    Returns:
        One row per pair × state with the columns :data:`COLUMNS`; Holm's adjustment runs over
        all rows.
    """
    names, states, wide = rmse_by_run(metrics)
    rows = [row for ref, est in itertools.combinations(names, 2) for row in _compare(wide, est, ref)]
    if not rows:
        return pd.DataFrame(columns=list(COLUMNS))
    out = pd.DataFrame(rows).merge(states, on="state", how="left")
    out["p_wilcoxon_holm"] = holm(out["p_wilcoxon"].to_numpy())
    out["p_ttest_holm"] = holm(out["p_ttest"].to_numpy())
    return out[list(COLUMNS)]


def percent_interval(low: float, high: float) -> str:
    """``[low, high]`` of a fraction in percent; ``[unbounded]`` where Fieller's set has no ends
    (the reference's mean RMSE not significantly above 0 at the runs used)."""
    if np.isnan(low) or np.isnan(high):
        return "[unbounded]"
    return f"[{100 * low:+.3g}, {100 * high:+.3g}]"


def summary_lines(table: pd.DataFrame) -> list[str]:
    """One line per pair: how many states differ at Holm-adjusted Wilcoxon p < 0.05, and the
    state with the smallest adjusted p (ties: the largest relative difference), as
    ``srukf - ekf: 2 of 12 states differ (Wilcoxon, Holm p < 0.05); vx -0.42 % [-0.61, -0.20],
    p_holm 0.001; 50 runs``."""
    lines = []
    family = int(table["p_wilcoxon"].notna().sum())  # the tests Holm's adjustment runs over
    for pair, rows in table.groupby("pair", sort=False):
        runs, excluded = int(rows["runs"].iloc[0]), int(rows["excluded_runs"].iloc[0])
        used = f"{runs} runs" + (f" ({excluded} excluded: diverged in either)" if excluded else "")
        tested = rows.dropna(subset=["p_wilcoxon_holm"])
        if tested.empty:
            lines.append(f"{pair}: not tested, {used}")
            continue
        significant = int((tested["p_wilcoxon_holm"] < SIGNIFICANCE).sum())
        best = tested.assign(size=-tested["rel_diff"].abs()).sort_values(["p_wilcoxon_holm", "size"]).iloc[0]
        lines.append(
            f"{pair}: {significant} of {len(rows)} states differ (Wilcoxon, Holm p < {SIGNIFICANCE:g}); "
            f"{best['state']} {100 * best['rel_diff']:+.3g} % "
            f"{percent_interval(best['rel_ci_low'], best['rel_ci_high'])}, "
            f"p_holm {best['p_wilcoxon_holm']:.2g}; {used}" + _unreachable(runs, family)
        )
    return lines


def smallest_wilcoxon_p(n: int) -> float:
    """The smallest two-sided p-value of the exact Wilcoxon signed-rank test on ``n`` non-zero
    differences: all of one sign, each of the ``2ⁿ`` sign patterns being equally likely under the
    null hypothesis (Wilcoxon 1945), so ``p = 2 · 2⁻ⁿ`` (1 for n ≤ 1)."""
    return min(1.0, 2.0 ** (1 - n))


def runs_to_reach(family: int, level: float = SIGNIFICANCE) -> int:
    """The fewest runs at which the smallest Holm-adjusted Wilcoxon p over ``family`` tests
    (``family · 2 · 2⁻ⁿ``, :func:`smallest_wilcoxon_p`: Holm multiplies the smallest p by the family
    size) falls below ``level``."""
    n = 1
    while family * smallest_wilcoxon_p(n) >= level:
        n += 1
    return n


def _unreachable(runs: int, family: int) -> str:
    """The note of a summary line whose test cannot reach significance at its run count ('' if it can)."""
    floor = min(1.0, family * smallest_wilcoxon_p(runs))
    if floor < SIGNIFICANCE:
        return ""
    return (f"; at {runs} runs no state can differ: the smallest attainable Holm p over {family} tests is {floor:.2g} "
            f"(Wilcoxon's 2/2^{runs}), >= {SIGNIFICANCE:g} (needs >= {runs_to_reach(family)} runs)")  # fmt: skip


def paired_markdown(table: pd.DataFrame) -> str:
    """The Markdown section of ``rmse_table.md`` (empty with fewer than two estimators): relative
    difference with its CI in percent and the Holm-adjusted p-values, one row per pair × state."""
    if table.empty:
        return ""
    rows = pd.DataFrame(
        {
            "pair": table["pair"],
            "state": table["state"],
            "runs": table["runs"],
            "mean diff": table["mean_diff"].map(lambda v: f"{v:+.3g}"),
            "diff % [95% CI]": [
                f"{100 * r:+.3g} {percent_interval(lo, hi)}"
                for r, lo, hi in zip(table["rel_diff"], table["rel_ci_low"], table["rel_ci_high"], strict=True)
            ],
            "p Wilcoxon (Holm)": table["p_wilcoxon_holm"].map(lambda v: f"{v:.2g}"),
            "p t-test (Holm)": table["p_ttest_holm"].map(lambda v: f"{v:.2g}"),
        }
    )
    title = (
        "\n## Paired differences (estimator - reference, per-run RMSE)\n\n"
        "Runs that diverged in either estimator of a pair are excluded from that pair. CI: 95 % Student-t "
        "interval over runs (of the ratio: Fieller's, from the paired runs). p-values: two-sided, "
        "Holm-adjusted over all pairs × states "
        "(paired_comparison.csv has the unadjusted ones).\n\n"
    )
    return title + markdown_table(rows)
