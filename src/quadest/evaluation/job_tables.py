"""The metric tables and ``summary.json`` entries every job writes (``docs/outputs.md``).

Each job kind (open loop, closed loop, flight-log replay: :mod:`quadest.app.pipeline`) computes its
:class:`MetricTables`; :func:`write_tables` is the one place that writes them to disk
(``metrics.csv``, ``rmse_summary.csv``, ``paired_comparison.csv``, ``rmse_table.md``), and
:func:`estimator_entries` makes every job's per-estimator entries of ``summary.json``."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
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
    preamble: str = ""
    """Text above the printed table in ``rmse_table.md`` (a replay's caption); empty for most jobs."""


def json_float(value) -> float | None:
    """A number for strict JSON: NaN becomes ``None``."""
    value = float(value)
    return None if np.isnan(value) else value


def metric_tables(
    results: list[EstimatorResult],
    data: MonteCarloData,
    params: dict[str, dict],
    labels: dict,
    bound: np.ndarray,
    seed: int,
) -> MetricTables:
    """The metric tables of a job whose results are errors against a truth (open and closed loop).

    ``labels`` become columns of ``metrics.csv``; ``bound`` is the PCRLB (K+1, n_err) or NaN.
    Nothing is written: :func:`write_tables` does that.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        table = tidy_metrics(results, data, params, labels)
        summary = summarize(table).merge(
            floor_table(results, data, bound), on=["estimator", "quantity", "state"], how="left"
        )
        overview = estimator_overview(results, data.model.n_err, data.model.m)
    printed = rmse_table(summary)
    return MetricTables(table, summary, overview, printed, paired_comparison(table, seed))


def with_cache_column(tables: MetricTables, from_cache: dict[str, bool]) -> MetricTables:
    """``tables`` with the column ``from_cache`` (estimator → whether its result was looked up in
    the result cache) in ``metrics.csv``, right after ``step_time_us``."""
    table = tables.table.copy()
    table.insert(table.columns.get_loc("step_time_us") + 1, "from_cache", table["estimator"].map(from_cache))
    return replace(tables, table=table)


def write_tables(out_dir: Path, tables: MetricTables) -> None:
    """Write ``metrics.csv``, ``rmse_summary.csv``, ``paired_comparison.csv`` and ``rmse_table.md``:
    the one writer of every job's metric tables."""
    tables.table.to_csv(out_dir / "metrics.csv", index=False)
    tables.summary.to_csv(out_dir / "rmse_summary.csv", index=False)
    tables.paired.to_csv(out_dir / "paired_comparison.csv", index=False)
    (out_dir / "rmse_table.md").write_text(
        tables.preamble + markdown_table(tables.printed) + "\n" + markdown_table(tables.overview.round(4))
        + paired_markdown(tables.paired)
    )  # fmt: skip


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
