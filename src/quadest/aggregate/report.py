"""Write a sweep's aggregate folder: ``jobs.csv``, ``cells.csv``, the tables (CSV, Markdown,
LaTeX), the figures and ``report.md``."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import yaml

from quadest.aggregate.figures import figures
from quadest.aggregate.statistics import paired_summary, tables, with_confidence_interval
from quadest.aggregate.sweep import load_paired, load_sweep
from quadest.aggregate.versus_best import heat_maps, run_scores, ut_parameter, versus_best
from quadest.formatting import latex_table, markdown_table, strict_json


def _write(frame: pd.DataFrame, out: Path, name: str) -> dict[str, str]:
    frame.to_csv(out / f"{name}.csv", index=False)
    (out / f"{name}.md").write_text(markdown_table(frame))
    (out / f"{name}.tex").write_text(latex_table(frame))
    return {"name": name, "md": markdown_table(frame)}


def aggregate(sweep_dir: Path) -> Path:
    """Aggregate ``sweep_dir`` into ``sweep_dir/aggregate/``; returns the path of ``report.md``."""
    sweep_dir = Path(sweep_dir)
    out = sweep_dir / "aggregate"
    (out / "figures").mkdir(parents=True, exist_ok=True)
    cells, jobs, params = load_sweep(sweep_dir)
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
                counts = against_best.groupby(["estimator", "group"], sort=False).agg(
                    cells=("job", "size"), differ_from_best=("differs", "sum")
                )
                written.append(_write(counts.reset_index(), out, "versus_best_counts"))
                made += heat_maps(against_best, params, out / "figures")
    commits = sorted({c for c in jobs.get("commit", pd.Series(dtype=str)).dropna() if c})
    multirun = sweep_dir / "multirun.yaml"
    sweep_cfg = yaml.safe_load(multirun.read_text()) if multirun.is_file() else {}
    hydra_cfg = (sweep_cfg or {}).get("hydra", {}) or {}
    lines = [
        f"# Sweep report: `{sweep_dir}`",
        "",
        f"- commit: {', '.join(commits) or 'unknown'}",
        f"- command-line overrides: `{' '.join(hydra_cfg.get('overrides', {}).get('task', []) or [])}`",
        f"- swept: {strict_json((hydra_cfg.get('sweeper') or {}).get('params') or {})}",
        f"- jobs: {len(jobs)}; " + ", ".join(f"{k}: {v}" for k, v in jobs["status"].value_counts().items()),
        "- the full config of every job is in `<job>/.hydra/config.yaml`; the sweep's in `multirun.yaml`",
        "",
    ]
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
