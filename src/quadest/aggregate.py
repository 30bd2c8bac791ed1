"""Aggregate a sweep folder into tables, figures and a report: ``quadest-aggregate SWEEP_DIR``.

Also run automatically at the end of a multirun by :class:`AggregateCallback`. It reads what each
job documented (``summary.json``, ``rmse_summary.csv``, ``.hydra/overrides.yaml``) and never
needs a job to have succeeded: failed jobs (``"status": "failed"``), jobs that never finished
(no ``summary.json``) and jobs that are missing from the grid are listed, and the rest is
aggregated. It can be re-run on any sweep folder (after SLURM, after a crash).

Writes into ``SWEEP_DIR/aggregate/``:

- ``cells.csv``: the tidy table, one row per job × estimator × state with the swept parameters
  and the group choices (``choice.sensor``, ...) as columns, the per-run RMSE mean, std and
  95 % confidence interval of the mean (Student t),
  the mean per-run MSE, pooled RMSE, PCRLB, diverged runs, NEES/NIS and time per step;
- ``rmse`` (per cell, estimator and state: ``mean ± std [95 % CI]``), ``best_cells``,
  ``divergence`` and ``timing`` tables as ``.csv``, ``.md`` and ``.tex``;
- ``jobs.csv``: every expected job and its status;
- ``figures/*.png`` and ``*.pdf``: RMSE vs α with one line per (β, κ); α × β heatmaps per state
  group; RMSE vs sensor error scale per estimator with 95 % error bars; a per-state RMSE bar chart;
- ``report.md``: all of the above, the commit and the sweep's overrides.

The "best cell" of an estimator minimises the mean over filter states of RMSE divided by the
smallest RMSE of that state in the whole sweep (a unit-free score).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import yaml
from hydra.experimental.callback import Callback
from scipy.stats import t as student_t

from quadest.job import markdown_table

# Columns the aggregate tables use themselves; an override with one of these names (``runs=20``)
# becomes ``override.<name>``.
OWN_COLUMNS = {"job", "status", "error", "commit", "estimator", "quantity", "state", "unit", "rmse_mean", "rmse_std",
               "mse_mean", "runs", "diverged", "pooled_rmse", "pcrlb", "step_time_us", "mean_nees", "nees_in_band",
               "mean_nis", "nis_in_band", "ci95_low", "ci95_high"}  # fmt: skip
STATE_GROUPS = {"m/s": "velocities", "rad/s": "angle rates", "rad": "angles", "m": "positions"}


def _value(text: str):
    """An override's value: a number where it is one (PyYAML reads ``1e-3`` as a string)."""
    try:
        return float(text) if "." in text or "e" in text.lower() else int(text)
    except ValueError:
        pass
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def _expected_jobs(sweep_dir: Path) -> int | None:
    """Number of jobs the sweep's grid holds (product of the comma lists in the sweeper params)."""
    path = sweep_dir / "multirun.yaml"
    if not path.is_file():
        return None
    cfg = yaml.safe_load(path.read_text()) or {}
    params = ((cfg.get("hydra") or {}).get("sweeper") or {}).get("params") or {}
    overrides = ((cfg.get("hydra") or {}).get("overrides") or {}).get("task") or []
    sizes = [len(str(v).split(",")) for v in params.values()]
    for item in overrides:
        key, _, value = str(item).partition("=")
        if "," in value and not value.startswith("[") and key not in params:
            sizes.append(len(value.split(",")))
    return int(np.prod(sizes)) if sizes else 1


def load_sweep(sweep_dir: Path) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(cells, jobs, parameter columns) of a sweep folder."""
    rows, jobs, params = [], [], []
    found = sorted((p for p in sweep_dir.iterdir() if p.is_dir() and p.name.isdigit()), key=lambda p: int(p.name))
    for job_dir in found:
        overrides_file = job_dir / ".hydra" / "overrides.yaml"
        overrides = yaml.safe_load(overrides_file.read_text()) if overrides_file.is_file() else []
        cell = {}
        for item in overrides or []:
            key, _, value = str(item).partition("=")
            key = key.lstrip("+~")
            key = f"override.{key}" if key in OWN_COLUMNS else key
            if not key.startswith("hydra"):
                cell[key] = _value(value)
                if key not in params:
                    params.append(key)
        hydra_file = job_dir / ".hydra" / "hydra.yaml"
        if hydra_file.is_file():
            choices = ((yaml.safe_load(hydra_file.read_text()) or {}).get("hydra", {}).get("runtime", {})
                       .get("choices", {}) or {})  # fmt: skip
            for group, choice in choices.items():
                if not group.startswith("hydra") and isinstance(choice, str):
                    cell.setdefault(f"choice.{group}", choice)
        summary_file = job_dir / "summary.json"
        if not summary_file.is_file():
            jobs.append({"job": int(job_dir.name), "status": "did not finish", "error": "", **cell})
            continue
        summary = json.loads(summary_file.read_text())
        jobs.append(
            {
                "job": int(job_dir.name),
                "status": summary.get("status", "unknown"),
                "error": summary.get("error", ""),
                "commit": summary.get("commit", ""),
                **cell,
            }
        )
        if summary.get("status") != "ok":
            continue
        table = pd.read_csv(job_dir / "rmse_summary.csv")
        for name, est in summary["estimators"].items():
            part = table[table["estimator"] == name].copy()
            part["job"] = int(job_dir.name)
            for key in ("step_time_us", "mean_nees", "nees_in_band", "mean_nis", "nis_in_band"):
                part[key] = est.get(key)
            for key, value in cell.items():
                part[key] = value if not isinstance(value, list) else str(value)
            rows.append(part)
    expected = _expected_jobs(sweep_dir)
    present = {j["job"] for j in jobs}
    total = max(expected or 0, max(present, default=-1) + 1)
    for missing in sorted(set(range(total)) - present):
        jobs.append({"job": missing, "status": "missing", "error": ""})
    cells = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()
    if not cells.empty:
        n = cells["runs"].clip(lower=1)
        half = student_t.ppf(0.975, (n - 1).clip(lower=1)) * cells["rmse_std"].fillna(0.0) / np.sqrt(n)
        cells["ci95_low"], cells["ci95_high"] = cells["rmse_mean"] - half, cells["rmse_mean"] + half
    return cells, pd.DataFrame(jobs).sort_values("job").reset_index(drop=True), params


def latex_table(frame: pd.DataFrame) -> str:
    """A plain LaTeX ``tabular`` (no jinja2 needed)."""

    def esc(v) -> str:
        return re.sub(r"([_%&#$])", r"\\\1", str(v)).replace("±", r"$\pm$")

    lines = [
        r"\begin{tabular}{" + "l" * len(frame.columns) + "}",
        r"\hline",
        " & ".join(esc(c) for c in frame.columns) + r" \\",
        r"\hline",
    ]
    lines += [" & ".join(esc(v) for v in row) + r" \\" for row in frame.itertuples(index=False)]
    return "\n".join([*lines, r"\hline", r"\end{tabular}"]) + "\n"


def _write(frame: pd.DataFrame, out: Path, name: str) -> dict[str, str]:
    frame.to_csv(out / f"{name}.csv", index=False)
    (out / f"{name}.md").write_text(markdown_table(frame))
    (out / f"{name}.tex").write_text(latex_table(frame))
    return {"name": name, "md": markdown_table(frame)}


def _fmt(m: float, s: float, lo: float, hi: float) -> str:
    return "-" if not np.isfinite(m) else f"{m:.4g} ± {s:.2g} [{lo:.4g}, {hi:.4g}]"


def tables(cells: pd.DataFrame, params: list[str]) -> dict[str, pd.DataFrame]:
    filt = cells[cells["quantity"] == "filter"]
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
    best_state = filt.groupby("state")["rmse_mean"].transform("min")
    score = filt.assign(score=filt["rmse_mean"] / best_state).groupby(keys, sort=False)["score"].mean().reset_index()
    best = score.loc[score.groupby("estimator", sort=False)["score"].idxmin()].round({"score": 3})
    per_job = filt.groupby(keys, sort=False).agg(diverged=("diverged", "max"), runs=("runs", "max")).reset_index()
    per_cell = filt.drop_duplicates(["job", "estimator"])
    timing = per_cell.groupby("estimator", sort=False)["step_time_us"].agg(["mean", "std", "count"]).reset_index()
    timing.columns = ["estimator", "step_time_us_mean", "step_time_us_std", "jobs"]
    return {"rmse": rmse, "best_cells": best, "divergence": per_job, "timing": timing.round(2)}


def _param(params: list[str], suffix: str) -> str | None:
    return next((p for p in params if p.split(".")[-1] == suffix), None)


def _save(fig, path: Path) -> list[Path]:
    fig.tight_layout()
    paths = [path.with_suffix(".png"), path.with_suffix(".pdf")]
    for p in paths:  # no creation date in the PDF, so regenerating gives the same file
        fig.savefig(p, dpi=110, metadata={"CreationDate": None} if p.suffix == ".pdf" else None)
    plt.close(fig)
    return paths


def _rmse_lines(axes, sel: pd.DataFrame, states: list[str], x: str, label: str) -> None:
    """One line per panel (state): RMSE against ``x`` with 95 % CI error bars."""
    for ax, state in zip(axes, states, strict=True):
        s = sel[sel["state"] == state].sort_values(x)
        yerr = [s["rmse_mean"] - s["ci95_low"], s["ci95_high"] - s["rmse_mean"]]
        ax.errorbar(s[x], s["rmse_mean"], yerr=yerr, marker="o", ms=3, capsize=2, label=label)


def _label_axes(axes, states: list[str], units: dict, xlabel: str, log_y: bool) -> None:
    for ax, state in zip(axes, states, strict=True):
        ax.set_xscale("log")
        if log_y:
            ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"RMSE {state} [{units[state]}]")
        ax.grid(alpha=0.3, which="both")


def figures(cells: pd.DataFrame, params: list[str], out: Path) -> list[Path]:
    made: list[Path] = []
    filt = cells[cells["quantity"] == "filter"]
    states = list(dict.fromkeys(filt["state"]))
    units = dict(zip(filt["state"], filt["unit"], strict=False))
    alpha, beta, kappa = _param(params, "alpha"), _param(params, "beta"), _param(params, "kappa")
    scale = _param(params, "error_scale")
    for est, part in filt.groupby("estimator", sort=False):
        if alpha:
            fig, axes = plt.subplots(1, len(states), figsize=(3.2 * len(states), 3.0), squeeze=False)
            swept = [c for c in (beta, kappa) if c]
            for combo in part[swept].drop_duplicates().itertuples(index=False):
                sel = part
                for c, v in zip(swept, combo, strict=True):
                    sel = sel[sel[c] == v]
                label = ", ".join(f"{c.split('.')[-1]}={v}" for c, v in zip(swept, combo, strict=True))
                _rmse_lines(axes[0], sel, states, alpha, label)
            _label_axes(axes[0], states, units, "α", log_y=False)
            axes[0, 0].legend(fontsize=7)
            fig.suptitle(f"{est}: RMSE vs α (95 % CI of the mean over runs)")
            made += _save(fig, out / f"rmse_vs_alpha_{est}")
        if alpha and beta:
            groups = list(dict.fromkeys(STATE_GROUPS.get(units[s], units[s]) for s in states))
            kappas = sorted(part[kappa].unique()) if kappa else [None]
            fig, axes = plt.subplots(
                len(kappas), len(groups), figsize=(3.6 * len(groups), 2.8 * len(kappas)), squeeze=False
            )
            for r, kv in enumerate(kappas):
                sel = part if kv is None else part[part[kappa] == kv]
                for c, group in enumerate(groups):
                    g = sel[sel["state"].map(lambda s: STATE_GROUPS.get(units[s], units[s])) == group]
                    grid = g.groupby([beta, alpha])["rmse_mean"].mean().unstack(alpha)
                    ax = axes[r, c]
                    im = ax.imshow(grid.to_numpy(), aspect="auto", origin="lower", cmap="viridis")
                    ax.set_xticks(range(grid.shape[1]), [f"{a:g}" for a in grid.columns], fontsize=7)
                    ax.set_yticks(range(grid.shape[0]), [f"{b:g}" for b in grid.index], fontsize=7)
                    ax.set_xlabel("α")
                    ax.set_ylabel("β")
                    ax.set_title(f"{group}" + (f", κ={kv:g}" if kv is not None else ""), fontsize=9)
                    unit = next((u for u, name in STATE_GROUPS.items() if name == group), group)
                    fig.colorbar(im, ax=ax, label=f"mean RMSE [{unit}]")
            fig.suptitle(f"{est}: mean RMSE per state group over α × β")
            made += _save(fig, out / f"alpha_beta_heatmap_{est}")
    if scale:
        grades = [p for p in params if p in ("sensor",)]
        fig, axes = plt.subplots(1, len(states), figsize=(3.2 * len(states), 3.0), squeeze=False)
        for keys, sel in filt.groupby(["estimator", *grades], sort=False):
            label = " / ".join(str(k) for k in (keys if isinstance(keys, tuple) else (keys,)))
            _rmse_lines(axes[0], sel, states, scale, label)
        _label_axes(axes[0], states, units, "sensor error scale", log_y=True)
        axes[0, 0].legend(fontsize=6)
        fig.suptitle("RMSE vs sensor error scale (95 % CI of the mean over runs)")
        made += _save(fig, out / "rmse_vs_error_scale")
    made += rmse_bars(cells, params, out / "rmse_bars")
    return made


def rmse_bars(cells: pd.DataFrame, params: list[str], path: Path) -> list[Path]:
    """Per-state RMSE bars with 95 % CI, one bar per estimator, at each estimator's best cell."""
    filt = cells[cells["quantity"] == "filter"]
    best = tables(cells, params)["best_cells"]
    states = list(dict.fromkeys(filt["state"]))
    units = dict(zip(filt["state"], filt["unit"], strict=False))
    fig, axes = plt.subplots(1, len(states), figsize=(2.6 * len(states), 3.0), squeeze=False)
    for i, row in enumerate(best.itertuples(index=False)):
        sel = filt[(filt["estimator"] == row.estimator) & (filt["job"] == row.job)]
        for ax, state in zip(axes[0], states, strict=True):
            s = sel[sel["state"] == state]
            ax.bar(
                i,
                s["rmse_mean"],
                yerr=[s["rmse_mean"] - s["ci95_low"], s["ci95_high"] - s["rmse_mean"]],
                capsize=3,
                label=row.estimator,
                color=f"C{i}",
            )
    for ax, state in zip(axes[0], states, strict=True):
        ax.set_xticks(range(len(best)), list(best["estimator"]), rotation=45, fontsize=7)
        ax.set_title(f"{state} [{units[state]}]", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle("Per-state RMSE (mean over runs, 95 % CI), best cell of each estimator")
    return _save(fig, path)


def aggregate(sweep_dir: Path) -> Path:
    """Aggregate ``sweep_dir``; returns the path of ``report.md``."""
    sweep_dir = Path(sweep_dir)
    out = sweep_dir / "aggregate"
    (out / "figures").mkdir(parents=True, exist_ok=True)
    cells, jobs, params = load_sweep(sweep_dir)
    jobs.to_csv(out / "jobs.csv", index=False)
    written, made = [], []
    if not cells.empty:
        cells.to_csv(out / "cells.csv", index=False)
        written = [_write(frame, out, name) for name, frame in tables(cells, params).items()]
        made = figures(cells, params, out / "figures")
    commits = sorted({c for c in jobs.get("commit", pd.Series(dtype=str)).dropna() if c})
    multirun = sweep_dir / "multirun.yaml"
    sweep_cfg = yaml.safe_load(multirun.read_text()) if multirun.is_file() else {}
    hydra_cfg = (sweep_cfg or {}).get("hydra", {}) or {}
    lines = [
        f"# Sweep report: `{sweep_dir}`",
        "",
        f"- commit: {', '.join(commits) or 'unknown'}",
        f"- command-line overrides: `{' '.join(hydra_cfg.get('overrides', {}).get('task', []) or [])}`",
        f"- swept: {json.dumps((hydra_cfg.get('sweeper') or {}).get('params') or {})}",
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


class AggregateCallback(Callback):
    """Hydra callback: aggregate the sweep folder when a multirun ends."""

    def on_multirun_end(self, config, **kwargs) -> None:
        report = aggregate(Path(config.hydra.sweep.dir))
        print(f"Aggregated: {report}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="quadest-aggregate", description="Aggregate a quadest sweep folder.")
    parser.add_argument("sweep_dir", type=Path, help="the multirun folder (holds 0/, 1/, ... and multirun.yaml)")
    args = parser.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"quadest-aggregate: error: {args.sweep_dir} is not a directory", file=sys.stderr)
        return 2
    print(f"Aggregated: {aggregate(args.sweep_dir)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
