"""Figures of a sweep: RMSE vs α with one line per (β, κ), α × β heatmaps per state group, RMSE
vs sensor error scale per estimator, and per-state RMSE bars at each estimator's best cell, with
95 % confidence intervals of the mean over runs; and in every sweep the cost–accuracy figure (RMSE
against the time per step). Each is saved as PNG and PDF."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pandas as pd

from quadest.aggregate.statistics import best_cells
from quadest.aggregate.versus_best import state_group


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
    """Every figure the swept parameters allow, saved into ``out``; returns the files written."""
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
            group_of = dict(zip(filt["state"], state_group(filt), strict=False))
            groups = list(dict.fromkeys(group_of[s] for s in states))
            kappas = sorted(part[kappa].unique()) if kappa else [None]
            fig, axes = plt.subplots(
                len(kappas), len(groups), figsize=(3.6 * len(groups), 2.8 * len(kappas)), squeeze=False
            )
            for r, kv in enumerate(kappas):
                sel = part if kv is None else part[part[kappa] == kv]
                for c, group in enumerate(groups):
                    g = sel[sel["state"].map(group_of) == group]
                    grid = g.groupby([beta, alpha])["rmse_mean"].mean().unstack(alpha)
                    ax = axes[r, c]
                    im = ax.imshow(grid.to_numpy(), aspect="auto", origin="lower", cmap="viridis")
                    ax.set_xticks(range(grid.shape[1]), [f"{a:g}" for a in grid.columns], fontsize=7)
                    ax.set_yticks(range(grid.shape[0]), [f"{b:g}" for b in grid.index], fontsize=7)
                    ax.set_xlabel("α")
                    ax.set_ylabel("β")
                    ax.set_title(f"{group}" + (f", κ={kv:g}" if kv is not None else ""), fontsize=9)
                    unit = units[next(s for s in states if group_of[s] == group)]
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
    made += cost_accuracy(cells, out / "cost_accuracy")
    return made


def cost_accuracy(cells: pd.DataFrame, path: Path) -> list[Path]:
    """What accuracy costs: per filter state, every cell's mean RMSE against its time per step and
    run (µs, log scale), one marker colour per estimator, so the estimators that are both fast and
    accurate sit at the lower left."""
    filt = cells[cells["quantity"] == "filter"]
    states = list(dict.fromkeys(filt["state"]))
    units = dict(zip(filt["state"], filt["unit"], strict=False))
    fig, axes = plt.subplots(1, len(states), figsize=(3.0 * len(states), 3.0), squeeze=False)
    for i, (est, part) in enumerate(filt.groupby("estimator", sort=False)):
        for ax, state in zip(axes[0], states, strict=True):
            s = part[part["state"] == state]
            ax.scatter(s["step_time_us"], s["rmse_mean"], s=12, color=f"C{i % 10}", label=est)
    for ax, state in zip(axes[0], states, strict=True):
        ax.set_xscale("log")
        ax.set_xlabel("time per step and run [µs]")
        ax.set_ylabel(f"RMSE {state} [{units[state]}]")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Cost and accuracy: mean RMSE over runs against the time per step, every cell")
    return _save(fig, path)


def rmse_bars(cells: pd.DataFrame, params: list[str], path: Path) -> list[Path]:
    """Per-state RMSE bars with 95 % CI, one bar per estimator, at each estimator's best cell."""
    filt = cells[cells["quantity"] == "filter"]
    best = best_cells(cells, params)
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
