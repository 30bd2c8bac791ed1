"""The metric tables and ``summary.json`` entries every job writes (``docs/outputs.md``): the
open-loop job (:mod:`quadest.app.job`), the closed loop (:mod:`quadest.closed_loop.job`) and the
flight-log replay (:mod:`quadest.app.replay_report`) share them."""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from quadest.evaluation.formatting import markdown_table
from quadest.evaluation.metrics import estimator_overview, floor_table, rmse_table, summarize, tidy_metrics
from quadest.evaluation.paired import paired_comparison, paired_markdown
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult

OVERVIEW_KEYS = ("mean_nees", "nees_in_band", "mean_nis", "nis_in_band", "step_time_us")
"""Columns of :func:`quadest.evaluation.metrics.estimator_overview` that go into each estimator's summary."""


@dataclass
class MetricTables:
    """``metrics.csv`` (``table``), ``rmse_summary.csv`` (``summary``), the per-estimator
    ``overview``, the printed RMSE table and the paired comparison of one job."""

    table: pd.DataFrame
    summary: pd.DataFrame
    overview: pd.DataFrame
    printed: pd.DataFrame
    paired: pd.DataFrame


def json_float(value) -> float | None:
    """A number for strict JSON: NaN becomes ``None``."""
    value = float(value)
    return None if np.isnan(value) else value


def write_metric_tables(
    out_dir: Path,
    results: list[EstimatorResult],
    data: MonteCarloData,
    params: dict[str, dict],
    labels: dict,
    bound: np.ndarray,
    seed: int,
    from_cache: dict[str, bool] | None = None,
) -> MetricTables:
    """Write ``metrics.csv``, ``rmse_summary.csv``, ``paired_comparison.csv`` and ``rmse_table.md``.

    ``labels`` become columns of ``metrics.csv``; ``bound`` is the PCRLB (K+1, n_err) or NaN;
    ``from_cache`` (estimator → bool) adds the column that says which results were looked up.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        table = tidy_metrics(results, data, params, labels)
        if from_cache is not None:
            table.insert(table.columns.get_loc("step_time_us") + 1, "from_cache", table["estimator"].map(from_cache))
        summary = summarize(table).merge(
            floor_table(results, data, bound), on=["estimator", "quantity", "state"], how="left"
        )
        overview = estimator_overview(results, data.model.n_err, data.model.m)
    table.to_csv(out_dir / "metrics.csv", index=False)
    summary.to_csv(out_dir / "rmse_summary.csv", index=False)
    printed = rmse_table(summary)
    paired = paired_comparison(table, seed)
    paired.to_csv(out_dir / "paired_comparison.csv", index=False)
    (out_dir / "rmse_table.md").write_text(
        markdown_table(printed) + "\n" + markdown_table(overview.round(4)) + paired_markdown(paired)
    )
    return MetricTables(table, summary, overview, printed, paired)


def estimator_entries(
    results: list[EstimatorResult], tables: MetricTables, params: dict[str, dict], from_cache: dict[str, bool]
) -> dict[str, dict]:
    """Each estimator's entry of ``summary.json``: parameters, divergence, NEES/NIS, time, RMSE."""
    entries = {}
    with warnings.catch_warnings():  # a sensor that never updated a live run: its NIS is None
        warnings.simplefilter("ignore", RuntimeWarning)
        for res, row in zip(results, tables.overview.to_dict("records"), strict=True):
            entries[res.name] = _entry(res, row, tables.summary, params[res.name], from_cache.get(res.name, False))
    return entries


def _entry(res: EstimatorResult, row: dict, summary: pd.DataFrame, parameters: dict, from_cache: bool) -> dict:
    rows = summary[summary["estimator"] == res.name]
    return {
        "parameters": parameters,
        "diverged": row["diverged"],
        "failure_reasons": {str(k): v for k, v in res.reasons.items()},
        **{key: json_float(row.get(key, np.nan)) for key in OVERVIEW_KEYS},
        "from_cache": from_cache,
        "nis_by_sensor": {
            sensor: json_float(np.nanmean(res.mean_sensor_nis(sensor))) if (~res.diverged).any() else None
            for sensor in res.sensor_nis
        },
        "rmse": {
            r["state"]: {"mean": json_float(r["rmse_mean"]), "std": json_float(r["rmse_std"]),
                         "pooled": json_float(r["pooled_rmse"]), "pcrlb": json_float(r["pcrlb"]),
                         "quantity": r["quantity"], "unit": r["unit"]}
            for r in rows.to_dict("records")
        },
    }  # fmt: skip
