"""Write a sweep's aggregate folder: ``jobs.csv``, ``cells.csv``, the tables (CSV, Markdown,
LaTeX), the figures and ``report.md``; or, at ``output: compact``, the compact aggregate of a large
grid (:mod:`quadest.aggregate.compact`)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import yaml

from quadest.aggregate.compact import CELL_TABLE, write_compact
from quadest.aggregate.figures import figures
from quadest.aggregate.statistics import paired_summary, tables, with_confidence_interval
from quadest.aggregate.sweep import load_paired, load_sweep, swept_parameters
from quadest.aggregate.versus_best import heat_maps, run_scores, ut_parameter, versus_best, versus_best_counts
from quadest.errors import ConfigError
from quadest.evaluation.formatting import latex_table, markdown_table, strict_json

OUTPUT_KEY = "hydra.callbacks.aggregate.output"
"""The key that chooses the aggregate's output (an argument of
:class:`~quadest.app.callbacks.AggregateCallback`, recorded in the sweep's ``multirun.yaml``)."""
OUTPUTS = ("full", "compact")


def check_output(value: object) -> str:
    """``value`` if it is one of :data:`OUTPUTS`; else :class:`ConfigError` naming :data:`OUTPUT_KEY`."""
    if value not in OUTPUTS:
        raise ConfigError(
            OUTPUT_KEY, value, "one of full, compact (compact: one row per cell, for large grids; docs/experiments.md)"
        )
    return str(value)


def sweep_output(sweep_dir: Path) -> str:
    """The output the sweep's own config asks for (:data:`OUTPUT_KEY` in ``multirun.yaml``), else
    ``full``."""
    path = Path(sweep_dir) / "multirun.yaml"
    record = (yaml.safe_load(path.read_text()) or {}) if path.is_file() else {}
    callback = (((record.get("hydra") or {}).get("callbacks") or {}).get("aggregate")) or {}
    return check_output(callback.get("output", "full"))


def _write(frame: pd.DataFrame, out: Path, name: str) -> dict[str, str]:
    frame.to_csv(out / f"{name}.csv", index=False)
    (out / f"{name}.md").write_text(markdown_table(frame))
    (out / f"{name}.tex").write_text(latex_table(frame))
    return {"name": name, "md": markdown_table(frame)}


def _full(sweep_dir: Path, out: Path, cells: pd.DataFrame, jobs: pd.DataFrame, params: list[str]):
    """Write the full aggregate's files into ``out``; returns the report's tables and the figures."""
    (out / "figures").mkdir(exist_ok=True)
    cells = with_confidence_interval(cells)
    jobs.to_csv(out / "jobs.csv", index=False)
    written, made = [], []
    if not cells.empty:
        cells.to_csv(out / "cells.csv", index=False)
        written = [_write(frame, out, name) for name, frame in tables(cells, params).items()]
        made = figures(cells, params, out / "figures")
        paired = load_paired(sweep_dir, jobs, params)
        if not paired.empty:
            paired.to_csv(out / "paired.csv", index=False)
            written.append(_write(paired_summary(paired, params), out, "paired_summary"))
        if ut_parameter(params, "alpha"):
            against_best = versus_best(run_scores(sweep_dir, jobs, params), params)
            if not against_best.empty:
                against_best.to_csv(out / "versus_best.csv", index=False)
                written.append(_write(versus_best_counts(against_best), out, "versus_best_counts"))
                made += heat_maps(against_best, params, out / "figures")
    return written, made


def aggregate(sweep_dir: Path, output: str = "full", wall_time: float | None = None) -> Path:
    """Aggregate ``sweep_dir`` into ``sweep_dir/aggregate/``, every table and figure (``full``) or
    the compact aggregate (``compact``); ``wall_time`` (s), if measured, goes into the report.
    Returns the path of ``report.md``."""
    output = check_output(output)
    sweep_dir = Path(sweep_dir)
    out = sweep_dir / "aggregate"
    out.mkdir(parents=True, exist_ok=True)
    cells, jobs, params = load_sweep(sweep_dir)
    if output == "compact":
        written, made = write_compact(sweep_dir, out, cells, jobs, params, wall_time)
    else:
        written, made = _full(sweep_dir, out, cells, jobs, params)
    commits = sorted({c for c in jobs.get("commit", pd.Series(dtype=str)).dropna() if c})
    multirun = sweep_dir / "multirun.yaml"
    sweep_cfg = yaml.safe_load(multirun.read_text()) if multirun.is_file() else {}
    hydra_cfg = (sweep_cfg or {}).get("hydra", {}) or {}
    lines = [
        f"# Sweep report: `{sweep_dir}`",
        "",
        f"- commit: {', '.join(commits) or 'unknown'}",
        f"- command-line overrides: `{' '.join(hydra_cfg.get('overrides', {}).get('task', []) or [])}`",
        f"- swept: {strict_json(swept_parameters(sweep_cfg or {}))}",
        f"- jobs: {len(jobs)}; " + ", ".join(f"{k}: {v}" for k, v in jobs["status"].value_counts().items()),
        "- the full config of every job is in `<job>/.hydra/config.yaml`; the sweep's in `multirun.yaml`",
    ]
    if wall_time is not None:
        lines.append(f"- wall time of the sweep: {wall_time:.0f} s")
    if output == "compact":
        lines += [
            f"- compact aggregate (`{OUTPUT_KEY}: compact`, docs/experiments.md): one row per cell in "
            f"[`{CELL_TABLE}`]({CELL_TABLE}); `quadest-aggregate SWEEP_DIR --output full` makes the full "
            "tables from the job folders",
        ]
    lines.append("")
    problems = jobs[jobs["status"] != "ok"]
    if not problems.empty:
        lines += ["## Jobs that did not succeed", "", markdown_table(problems[["job", "status", "error"]]), ""]
    for table in written:
        lines += [f"## {table['name'].replace('_', ' ')}", "", table["md"], ""]
    for fig in made:
        if fig.suffix == ".png":
            lines += [f"![{fig.stem}](figures/{fig.name})", ""]
    report = out / "report.md"
    report.write_text("\n".join(lines))
    return report
