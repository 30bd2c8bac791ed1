"""The one job pipeline: open loop, closed loop and flight-log replay alike.

:func:`run_pipeline` writes ``config.yaml``, makes the job's data (through the result cache),
runs every estimator (:func:`~quadest.app.estimator_runs.run_estimators`: the same cache path,
worker policy and failure isolation for every kind), turns the results into table rows
(:func:`table_rows`), asks the job kind for its report, and writes the metric tables
(:func:`~quadest.evaluation.job_tables.write_tables`), ``timeseries.npz`` and ``summary.json``:
the one writer of each. A job kind (:class:`JobKind`) says only what differs: how the data is
made, what to do with one estimator, and what the report holds (tables, time series, the
summary's own fields, the kind's own files and figures). The output folder's layout is
``docs/outputs.md`` (schema version :data:`SCHEMA_VERSION`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from omegaconf import DictConfig, OmegaConf

from quadest.app.estimator_runs import RunSettings, Work, run_estimators
from quadest.app.provenance import provenance
from quadest.app.settings import JobSettings, data_key
from quadest.cache.lookup import JobCache
from quadest.estimators.registry import estimator_parameters
from quadest.evaluation.formatting import strict_json
from quadest.evaluation.job_tables import (
    MetricTables,
    estimator_entries,
    overview_keys,
    with_cache_column,
    write_tables,
)
from quadest.evaluation.paired import summary_lines
from quadest.montecarlo.results import EstimatorResult

SCHEMA_VERSION = 1


@dataclass
class TableRows:
    """The rows of a job's tables, time series and ``summary.json`` (one per result), with the
    parameters and the cache flag of each row's estimator."""

    results: list[EstimatorResult]
    params: dict[str, dict]
    from_cache: dict[str, bool]


def table_rows(results: list[EstimatorResult], params: dict[str, dict], from_cache: dict[str, bool]) -> TableRows:
    """The one place that turns the estimators' results (one per estimator, in the job's order)
    into rows: one row per estimator, followed by its smoothed row when it has a smoother
    (``<label>+smoothed`` / ``<label>+lag<L>``, with the estimator's parameters and cache flag)."""
    rows, row_params, row_cache = [], dict(params), dict(from_cache)
    for result in results:
        rows.append(result)
        if result.smoothed is not None:
            rows.append(result.smoothed)
            row_params[result.smoothed.name] = row_params.get(result.name, {})
            row_cache[result.smoothed.name] = row_cache.get(result.name, False)
    return TableRows(rows, row_params, row_cache)


@dataclass
class Finished:
    """What a job kind's report is made from, once every estimator has run."""

    out_dir: Path
    data: Any
    """The value of :meth:`JobKind.make_data` (from the cache or made by this job)."""
    results: list[EstimatorResult]
    """One per estimator, in the job's order."""
    rows: TableRows
    saved_runs: int
    derived: Callable[[str, Callable[[], Any]], Any]
    """``derived(name, compute)``: a value computed from the job's data alone (the PCRLB), through
    the result cache (:meth:`quadest.cache.lookup.JobCache.derived`)."""


@dataclass
class Report:
    """What a job kind reports; the pipeline writes it."""

    tables: MetricTables
    """``metrics.csv``, ``rmse_summary.csv``, ``paired_comparison.csv``, ``rmse_table.md``."""
    fields: dict[str, Any]
    """The kind's own fields of ``summary.json`` (labels, names, notes), in order."""
    series: dict[str, np.ndarray] = field(default_factory=dict)
    """``timeseries.npz`` (none if empty)."""
    caption: str | None = None
    """Printed above the table (``None``: the CLI's default caption)."""
    after_table: str | None = None
    """Printed below the table (the replay's differences to its offline reference)."""


class JobKind(Protocol):
    """What differs between the job kinds (open loop, closed loop, replay)."""

    caches_data: bool
    """Whether :meth:`make_data`'s value goes into the result cache under the data key."""

    def make_data(self) -> Any:
        """The data every estimator runs on (or the scaffold its results are scored with); it
        depends on the data key's settings only (``docs/cache.md``)."""
        ...

    def work(self, data: Any) -> Work:
        """What to do with one estimator, given :meth:`make_data`'s value."""
        ...

    def report(self, finished: Finished) -> Report:
        """The tables, time series and summary fields; writes the kind's own files (figures,
        control tables, ``convergence.csv``)."""
        ...


def run_pipeline(
    kind: JobKind, job: JobSettings, cfg: DictConfig, out_dir: Path, overrides: list[str] | None = None
) -> dict:
    """Run one job of ``kind`` with the typed settings ``job`` of the validated config ``cfg`` and
    write every output into ``out_dir``. ``cfg`` itself is only written (``config.yaml``) and hashed
    into the data key (:func:`quadest.app.settings.data_key`); everything else reads ``job``.
    Returns the JSON summary, with the printed table (``_table``), the paired lines (``_paired``)
    and, where the kind has them, the caption (``_caption``) and the text below the table
    (``_after_table``) for the CLI."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    exp = job.experiment
    cache = JobCache.for_job(exp.cache, data_key(cfg) if exp.cache.enabled else None)
    data, data_from_cache = cache.data(kind.make_data) if kind.caches_data else (kind.make_data(), False)
    nodes = exp.estimator
    params = {label: {"kind": node.get("kind", label), **estimator_parameters(node)} for label, node in nodes.items()}
    settings = RunSettings(float(exp.divergence_bound), min(int(exp.output.saved_runs), int(exp.runs)),
                           bool(exp.progress))  # fmt: skip
    results, from_cache = run_estimators(kind.work(data), nodes, cache, settings, int(exp.workers))
    rows = table_rows(results, params, from_cache)
    report = kind.report(Finished(out_dir, data, results, rows, settings.saved_runs, cache.derived))
    write_tables(out_dir, with_cache_column(report.tables, rows.from_cache))
    if report.series:
        np.savez_compressed(out_dir / "timeseries.npz", **report.series)
    summary = {
        "schema_version": SCHEMA_VERSION,
        "status": "ok",
        **provenance(),
        "overrides": list(overrides or []),
        **report.fields,
        "metric_keys": overview_keys(report.tables.overview),
        "cache": {"enabled": bool(exp.cache.enabled), "data_from_cache": data_from_cache},
        "estimators": estimator_entries(rows.results, report.tables, rows.params, rows.from_cache),
    }
    write_summary(out_dir, summary)
    summary["_table"] = report.tables.printed
    summary["_paired"] = summary_lines(report.tables.paired)
    if report.caption is not None:
        summary["_caption"] = report.caption
    after = "\n".join(text for text in (report.tables.further, report.after_table) if text)
    if after:
        summary["_after_table"] = after
    return summary


def write_summary(out_dir: Path, summary: dict) -> None:
    """Write ``summary.json`` (strict JSON): the one writer of a job's summary."""
    (out_dir / "summary.json").write_text(strict_json(summary, indent=2))
