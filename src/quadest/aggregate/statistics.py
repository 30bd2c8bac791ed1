"""Statistics of a sweep's cells: confidence intervals of the mean RMSE and the aggregate tables
(RMSE per cell, best cell per estimator, divergence, timing)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import t as student_t

from quadest.evaluation.paired import SIGNIFICANCE


def with_confidence_interval(cells: pd.DataFrame) -> pd.DataFrame:
    """``cells`` with ``ci95_low``/``ci95_high``: the 95 % confidence interval of the mean per-run
    RMSE, ``mean ± t_{0.975, n−1} · std / √n`` (Student t, n runs)."""
    if cells.empty:
        return cells
    n = cells["runs"].clip(lower=1)
    half = student_t.ppf(0.975, (n - 1).clip(lower=1)) * cells["rmse_std"].fillna(0.0) / np.sqrt(n)
    return cells.assign(ci95_low=cells["rmse_mean"] - half, ci95_high=cells["rmse_mean"] + half)


def _filter_states(cells: pd.DataFrame) -> pd.DataFrame:
    return cells[cells["quantity"] == "filter"]


def best_cells(cells: pd.DataFrame, params: list[str]) -> pd.DataFrame:
    """Each estimator's best cell: the one minimising the mean over filter states of RMSE divided
    by the smallest RMSE of that state in the whole sweep (a unit-free score)."""
    filt = _filter_states(cells)
    keys = ["job", *params, "estimator"]
    best_state = filt.groupby("state")["rmse_mean"].transform("min")
    score = filt.assign(score=filt["rmse_mean"] / best_state).groupby(keys, sort=False)["score"].mean().reset_index()
    return score.loc[score.groupby("estimator", sort=False)["score"].idxmin()].round({"score": 3})


def _fmt(m: float, s: float, lo: float, hi: float) -> str:
    return "-" if not np.isfinite(m) else f"{m:.4g} ± {s:.2g} [{lo:.4g}, {hi:.4g}]"


def tables(cells: pd.DataFrame, params: list[str]) -> dict[str, pd.DataFrame]:
    """The aggregate tables by name: ``rmse`` (``mean ± std [95 % CI]`` per cell, estimator and
    state), ``best_cells``, ``divergence`` (per cell and estimator) and ``timing`` (per estimator)."""
    filt = _filter_states(cells)
    keys = ["job", *params, "estimator"]
    rmse = filt.assign(
        cell=[
            _fmt(*v)
            for v in zip(
                filt["rmse_mean"], filt["rmse_std"].fillna(0), filt["ci95_low"], filt["ci95_high"], strict=True
            )
        ]
    )
    rmse = rmse.pivot_table(index=keys, columns="state", values="cell", aggfunc="first", sort=False).reset_index()
    rmse.columns.name = None
    per_job = filt.groupby(keys, sort=False).agg(diverged=("diverged", "max"), runs=("runs", "max")).reset_index()
    return {"rmse": rmse, "best_cells": best_cells(cells, params), "divergence": per_job, "timing": timing_table(cells)}


def timing_table(cells: pd.DataFrame) -> pd.DataFrame:
    """Per estimator: mean and std over the jobs of its time per step and run (µs), and the jobs."""
    per_cell = _filter_states(cells).drop_duplicates(["job", "estimator"])
    timing = per_cell.groupby("estimator", sort=False)["step_time_us"].agg(["mean", "std", "count"]).reset_index()
    timing.columns = ["estimator", "step_time_us_mean", "step_time_us_std", "jobs"]
    return timing.round(2)


def paired_summary(paired: pd.DataFrame, params: list[str]) -> pd.DataFrame:
    """Per cell and pair of estimators: how many filter states differ at Holm-adjusted Wilcoxon
    p < 0.05 (Holm over the cell's pairs × states), and the state with the smallest adjusted p
    with its relative difference and its 95 % Fieller CI in percent."""
    if paired.empty:
        return pd.DataFrame()
    rows = []
    filt = paired[paired["quantity"] == "filter"]
    for (job, pair), part in filt.groupby(["job", "pair"], sort=False):
        tested = part.dropna(subset=["p_wilcoxon_holm"])
        best = tested.sort_values("p_wilcoxon_holm").iloc[0] if not tested.empty else None
        rows.append(
            {
                "job": job,
                **{key: part[key].iloc[0] for key in params},
                "pair": pair,
                "runs": int(part["runs"].iloc[0]),
                "states differing": f"{int((tested['p_wilcoxon_holm'] < SIGNIFICANCE).sum())} of {len(part)}",
                "smallest p state": "" if best is None else best["state"],
                "diff % [95% CI]": ""
                if best is None
                else (
                    f"{100 * best['rel_diff']:+.3g} [{100 * best['rel_ci_low']:+.3g}, {100 * best['rel_ci_high']:+.3g}]"
                ),
                "p Wilcoxon (Holm)": "" if best is None else f"{best['p_wilcoxon_holm']:.2g}",
            }
        )
    return pd.DataFrame(rows)
