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

import itertools
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from omegaconf import DictConfig, OmegaConf

from quadest.app.estimator_runs import RunSettings, Work, run_estimators
from quadest.app.provenance import provenance
from quadest.app.schema import ExperimentConf
from quadest.app.settings import JobSettings, data_key
from quadest.app.sizing import is_long
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
    series: dict[str, np.ndarray]
    """``timeseries.npz`` (none if empty)."""
    caption: str
    """Printed above the table (:func:`quadest.evaluation.captions.table_caption`)."""
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


@dataclass
class Progress:
    """A long job's progress lines on stderr (``quadest: progress: ...``, with the seconds since the
    job began): when the data is made and as each estimator is done. A job is long from
    :data:`~quadest.app.sizing.LONG_JOB_RUN_STEPS` run-steps on, and only with ``progress: true``
    (the per-step bars of a terminal stay as they are)."""

    enabled: bool
    start: float = field(default_factory=time.perf_counter)

    @classmethod
    def of(cls, exp: ExperimentConf) -> Progress:
        simulated = exp.source is None  # a replay is one log
        return cls(bool(exp.progress) and simulated and is_long(exp.runs, exp.duration, exp.sample_period))

    def line(self, text: str) -> None:
        if self.enabled:
            print(f"quadest: progress: {text} ({time.perf_counter() - self.start:.0f} s)", file=sys.stderr, flush=True)

    def estimator_done(self, total: int) -> Callable[[str], None] | None:
        if not self.enabled:
            return None
        count = itertools.count(1)
        return lambda label: self.line(f"{label} done, {next(count)} of {total} estimators")


def run_pipeline(
    kind: JobKind, job: JobSettings, cfg: DictConfig, out_dir: Path, overrides: list[str] | None = None
) -> dict:
    """Run one job of ``kind`` with the typed settings ``job`` of the validated config ``cfg`` and
    write every output into ``out_dir``. ``cfg`` itself is only written (``config.yaml``) and hashed
    into the data key (:func:`quadest.app.settings.data_key`); everything else reads ``job``.
    Returns the JSON summary, with the printed table (``_table``), the paired lines (``_paired``)
    the caption (``_caption``) and, where the kind has it, the text below the table
    (``_after_table``) for the CLI."""
    out_dir = start_job(cfg, out_dir)
    exp = job.experiment
    cache = job_cache(job, cfg)
    progress = Progress.of(exp)
    progress.line(f"making the data: {exp.runs} runs of {exp.duration:g} s at sample_period={exp.sample_period:g} s")
    data, data_from_cache = cache.data(kind.make_data) if kind.caches_data else (kind.make_data(), False)
    settings = run_settings(job, int(exp.runs))
    progress.line(f"running {len(exp.estimator)} estimator(s)")
    results, from_cache = run_estimators(kind.work(data), exp.estimator, cache, settings, int(exp.workers),
                                         progress.estimator_done(len(exp.estimator)))  # fmt: skip
    return finish_job(kind, job, out_dir, overrides, Ran(data, data_from_cache, results, from_cache, cache.derived))


def job_cache(job: JobSettings, cfg: DictConfig) -> JobCache:
    """The result cache of the job with settings ``job`` of the validated config ``cfg``: its data
    under the data key of ``cfg`` (:func:`quadest.app.settings.data_key`), none if ``cache.enabled``
    is false."""
    exp = job.experiment
    return JobCache.for_job(exp.cache, data_key(cfg) if exp.cache.enabled else None)


def start_job(cfg: DictConfig, out_dir: Path) -> Path:
    """Make ``out_dir`` and write ``config.yaml`` (the resolved config): the first thing a job does."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    return out_dir


def run_settings(job: JobSettings, runs: int) -> RunSettings:
    """The runner settings of a job of ``runs`` runs (the saved runs are at most ``runs``)."""
    exp = job.experiment
    return RunSettings(float(exp.divergence_bound), min(int(exp.output.saved_runs), runs), bool(exp.progress))


@dataclass
class Ran:
    """What a job computed (or found in the cache) before its report: its data, each estimator's
    result (in the job's order) and where each came from, and the cache of values derived from
    the data (:attr:`Finished.derived`)."""

    data: Any
    data_from_cache: bool
    results: list[EstimatorResult]
    from_cache: dict[str, bool]
    derived: Callable[[str, Callable[[], Any]], Any]


def estimator_params(nodes: dict[str, dict]) -> dict[str, dict]:
    """Each estimator's parameters in the tables and ``summary.json``: label → its ``kind`` and
    every parameter of its resolved config node ``nodes[label]``."""
    return {label: {"kind": node.get("kind", label), **estimator_parameters(node)} for label, node in nodes.items()}


def finish_job(kind: JobKind, job: JobSettings, out_dir: Path, overrides: list[str] | None, ran: Ran) -> dict:
    """The report of a job that has run (:func:`run_pipeline`): the tables, ``timeseries.npz`` and
    ``summary.json`` written, the summary returned with its printed parts."""
    exp = job.experiment
    saved_runs = run_settings(job, int(exp.runs)).saved_runs
    rows = table_rows(ran.results, estimator_params(exp.estimator), ran.from_cache)
    report = kind.report(Finished(out_dir, ran.data, ran.results, rows, saved_runs, ran.derived))
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
        "cache": {"enabled": bool(exp.cache.enabled), "data_from_cache": ran.data_from_cache},
        "estimators": estimator_entries(rows.results, report.tables, rows.params, rows.from_cache),
    }
    write_summary(out_dir, summary)
    summary["_table"] = report.tables.printed
    summary["_paired"] = summary_lines(report.tables.paired)
    summary["_caption"] = report.caption
    after = "\n".join(text for text in (report.tables.further, report.after_table) if text)
    if after:
        summary["_after_table"] = after
    return summary


def write_summary(out_dir: Path, summary: dict) -> None:
    """Write ``summary.json`` (strict JSON): the one writer of a job's summary."""
    (out_dir / "summary.json").write_text(strict_json(summary, indent=2))
