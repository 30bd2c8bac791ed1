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
from quadest.evaluation.metrics import (
    estimator_overview,
    floor_table,
    metric_summary,
    rmse_table,
    summarize,
    tidy_metrics,
)
from quadest.evaluation.paired import paired_comparison, paired_markdown
from quadest.metrics.settings import MetricsConf
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult

OVERVIEW_KEYS = ("mean_nees", "nees_in_band", "mean_nis", "nis_in_band", "step_time_us")
"""Columns of :func:`quadest.evaluation.metrics.estimator_overview` that go first into each
estimator's summary; every further overview column follows them (:func:`overview_keys`)."""
NOT_IN_SUMMARY = ("estimator", "diverged", "runs", "nees_dof", "nis_dof")
"""Overview columns that ``summary.json`` holds elsewhere (or not at all: the dof are the job's)."""
SUMMARY_STATS = {"rmse_mean": "mean", "rmse_std": "std", "pooled_rmse": "pooled", "pcrlb": "pcrlb"}
"""``rmse_summary.csv`` columns and their names in ``summary.json``'s per-state ``rmse`` entries."""


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
    further: str = ""
    """The further measures in short (:func:`further_measures`), printed after the table and at the
    end of ``rmse_table.md``."""


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
    settings: MetricsConf | None = None,
) -> MetricTables:
    """The metric tables of a job whose results are errors against a truth (open and closed loop).

    ``labels`` become columns of ``metrics.csv``; ``bound`` is the PCRLB (K+1, n_err) or NaN;
    ``settings`` the windows of the windowed measures (default: :class:`MetricsConf`'s).
    Nothing is written: :func:`write_tables` does that.
    """
    keys = ["estimator", "quantity", "state"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        table = tidy_metrics(results, data, params, labels)
        summary = summarize(table).merge(floor_table(results, data, bound), on=keys, how="left")
        summary = summary.merge(metric_summary(results, table, data.model, settings or MetricsConf()), on=keys)
        overview = estimator_overview(results, data.model)
    printed = rmse_table(summary)
    further = further_measures(summary, overview)
    return MetricTables(table, summary, overview, printed, paired_comparison(table), further=further)


def further_measures(summary: pd.DataFrame, overview: pd.DataFrame) -> str:
    """The measures beside the RMSE in short (docs/metrics.md): per filter state (every row where
    there are none) and estimator the median and 95th percentile of the absolute error and the time
    to converge; per estimator the credibility indices, the NEES band share of each state group and
    the NIS and its band share of each measurement group."""
    rows = summary[summary["quantity"] == "filter"] if (summary["quantity"] == "filter").any() else summary

    def cell(r) -> str:
        settle = "-" if not np.isfinite(r["time_to_converge_s"]) else f"{r['time_to_converge_s']:.2g} s"
        return f"{r['abs_error_median']:.3g} / {r['abs_error_p95']:.3g} / {settle}"

    text = rows.assign(
        cell=[cell(r) for r in rows.to_dict("records")],
        row=[f"{s} [{u}]" for s, u in zip(rows["state"], rows["unit"], strict=True)],
    )
    wide = text.pivot_table(index="row", columns="estimator", values="cell", aggfunc="first", sort=False)
    wide.columns.name = None
    lines = [
        "Median / 95th percentile of |error| over the steps (the median over runs of the per-run medians, the mean "
        "of the per-run 95th percentiles) / time to converge (docs/metrics.md; -: not settled by the end):",
        wide.reset_index().rename(columns={"row": "state"}).to_string(index=False),
    ]
    groups = [c for c in overview.columns if c.startswith("nees_in_band_")]
    if "nci" in overview:
        lines.append("Credibility (Li, Zhao & Jilkov 2002; dB, 0 = credible, inclination > 0 optimistic) and the "
                     "NEES band share per state group:")  # fmt: skip
        for r in overview.to_dict("records"):
            shares = ", ".join(f"{g.removeprefix('nees_in_band_')} {_share(r[g])}" for g in groups)
            nci, inclination = _number(r["nci"]), _number(r["inclination"], "+")
            lines.append(f"  {r['estimator']:>8s}: NCI {nci}, inclination {inclination}; in band: {shares}")
    measured = [c.removeprefix("nis_in_band_") for c in overview.columns if c.startswith("nis_in_band_")]
    if measured:
        lines.append("NIS per measurement group (the mean over runs and its steps; χ²(group size) when consistent) "
                     "and its band share:")  # fmt: skip
        for r in overview.to_dict("records"):
            shares = ", ".join(f"{g} {_mean(r[f'nis_{g}'])} ({_share(r[f'nis_in_band_{g}'])})" for g in measured)
            lines.append(f"  {r['estimator']:>8s}: {shares}")
    return "\n".join(lines) + "\n\n"


def _mean(value: float) -> str:
    return "n/a" if not np.isfinite(value) else f"{value:.3g}"


def _number(value: float, sign: str = "") -> str:
    return "n/a" if not np.isfinite(value) else f"{value:{sign}.2f} dB"


def _share(value: float) -> str:
    return "n/a" if not np.isfinite(value) else f"{100 * value:.0f}%"


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
    further = f"\n```\n{tables.further}```\n" if tables.further else ""
    (out_dir / "rmse_table.md").write_text(
        tables.preamble + markdown_table(tables.printed) + "\n" + markdown_table(tables.overview.round(4))
        + paired_markdown(tables.paired) + further
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


def overview_keys(overview: pd.DataFrame) -> list[str]:
    """The overview columns each estimator's ``summary.json`` entry holds, in order."""
    further = [c for c in overview.columns if c not in OVERVIEW_KEYS and c not in NOT_IN_SUMMARY]
    return [*OVERVIEW_KEYS, *further]


def summary_state_columns(summary: pd.DataFrame) -> list[str]:
    """The metrics' columns of ``rmse_summary.csv`` beyond the RMSE statistics, in order."""
    fixed = {"estimator", "quantity", "state", "unit", "group", "rmse_mean", "rmse_std", "mse_mean", "runs", "diverged"}
    return [c for c in summary.columns if c not in fixed and c not in SUMMARY_STATS]


def _entry(res: EstimatorResult, row: dict, summary: pd.DataFrame, parameters: dict, from_cache: bool) -> dict:
    rows = summary[summary["estimator"] == res.name]
    further = summary_state_columns(summary)
    return {
        "parameters": parameters,
        "diverged": row["diverged"],
        "failure_reasons": {str(k): v for k, v in res.reasons.items()},
        **{key: json_float(row.get(key, np.nan)) for key in overview_keys(pd.DataFrame([row]))},
        "from_cache": from_cache,
        "nis_by_sensor": {
            sensor: json_float(np.nanmean(res.mean_sensor_nis(sensor))) if (~res.diverged).any() else None
            for sensor in res.sensor_nis
        },
        "rmse": {
            r["state"]: {"mean": json_float(r["rmse_mean"]), "std": json_float(r["rmse_std"]),
                         "pooled": json_float(r["pooled_rmse"]), "pcrlb": json_float(r["pcrlb"]),
                         "quantity": r["quantity"], "unit": r["unit"],
                         **{c: json_float(r[c]) for c in further}}
            for r in rows.to_dict("records")
        },
    }  # fmt: skip
