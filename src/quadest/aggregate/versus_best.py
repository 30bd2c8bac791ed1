"""Which cells of a sigma-point parameter sweep differ from the best cell beyond the paired 95 % CI.

In a sweep over the UT parameters (α, β, κ) every cell with the same other settings (sensor level,
scenario, ...) filters the same truth and measurements: the data do not depend on an estimator's
parameters (docs/cache.md), so run ``i`` of two such cells is a paired sample. Such a set of cells
is a *panel*. For each estimator, panel and state group (the groups the model declares, ``group``
of ``metrics.csv``: velocities, angle rates, angles on the quadrotor), a run's score is the mean of
its per-run RMSE over the group's states; the *best* cell has the smallest mean score, and every
cell gets the paired difference to it, ``d_i = score_cell,i − score_best,i`` over the runs that
diverged in neither, with the Student t 95 % interval of the mean difference, ``d̄ ± t_{0.975, n−1}
s_d / √n``. A cell *differs* from the best when that interval lies above zero. Per-run differences
below :data:`quadest.evaluation.paired.ROUND_OFF` times the best score count as zero (filters equal
in exact arithmetic differ at round-off, systematically: docs of :mod:`quadest.evaluation.paired`).
The intervals are per cell, not simultaneous over the grid: with many cells a few "differs" are
expected by chance among cells that do not.

Reads each job's ``metrics.csv`` (per-run RMSE), so it needs the job folders of the sweep; the
aggregate writes ``versus_best.csv`` and one heat map per estimator and state group
(``figures/versus_best_<estimator>_<group>.png``): α × β per κ (rows) and panel (columns), the
mean score in colour, a dot on each cell that differs from its panel's best, a star on the best.
An estimator whose cells all give the same scores (one that does not take the swept parameters,
such as the EKF or a baseline at fixed parameters) is left out.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from PIL import Image

from quadest.evaluation.intervals import mean_and_half_width
from quadest.evaluation.paired import CONFIDENCE, ROUND_OFF

UT_PARAMETERS = ("alpha", "beta", "kappa")
GROUPS = {"m/s": "velocities", "rad/s": "angle rates", "rad": "angles", "m": "positions"}
"""State groups by unit, for a ``metrics.csv`` written before it had the model's ``group`` column."""


def state_group(rows: pd.DataFrame) -> pd.Series:
    """Each row's state group: the model's declaration (``group``,
    :attr:`quadest.models.base.FilterModel.state_groups`, underscores shown as spaces), else the
    group of its unit (:data:`GROUPS`)."""
    by_unit = rows["unit"].map(lambda u: GROUPS.get(u, u))
    if "group" not in rows:
        return by_unit
    declared = rows["group"].where(rows["group"].notna() & (rows["group"] != ""))
    return declared.str.replace("_", " ").fillna(by_unit)


def ut_parameter(params: list[str], name: str) -> str | None:
    """The swept column whose last part is ``name`` (``sweep.alpha`` for ``alpha``), if any."""
    return next((p for p in params if p.split(".")[-1] == name), None)


def run_scores(sweep_dir: Path, jobs: pd.DataFrame, params: list[str]) -> pd.DataFrame:
    """One row per job × estimator × state group × run: the run's mean RMSE over the group's
    filter states and whether it diverged, with the swept parameters as columns."""
    frames = []
    for row in jobs[jobs["status"] == "ok"].to_dict("records"):
        path = Path(sweep_dir) / str(row["job"]) / "metrics.csv"
        if not path.is_file():
            continue
        metrics = pd.read_csv(path)
        metrics = metrics[metrics["quantity"] == "filter"]
        metrics = metrics.assign(group=state_group(metrics))
        score = metrics.groupby(["estimator", "group", "run"], sort=False).agg(
            score=("rmse", "mean"), diverged=("diverged", "any")
        )
        score = score.reset_index()
        score["job"] = int(row["job"])
        for key in params:
            score[key] = row.get(key)
        frames.append(score)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def paired_interval(diff: np.ndarray) -> tuple[float, float, float]:
    """Mean of the paired differences and its Student t interval at :data:`CONFIDENCE`."""
    n = diff.size
    if n < 2:
        return (float(diff.mean()) if n else np.nan), np.nan, np.nan
    half = float(mean_and_half_width(diff, 1.0 - CONFIDENCE)[1])
    return float(diff.mean()), float(diff.mean() - half), float(diff.mean() + half)


def versus_best(scores: pd.DataFrame, params: list[str]) -> pd.DataFrame:
    """Per job, estimator and state group: the mean score, the panel's best job, the paired
    difference to it with its 95 % CI, and ``differs`` (see the module docstring)."""
    if scores.empty:
        return pd.DataFrame()
    panel = [p for p in params if p.split(".")[-1] not in UT_PARAMETERS]
    rows = []
    for keys, part in scores.groupby(["estimator", "group", *panel], sort=False, dropna=False):
        wide = part.pivot_table(index="run", columns="job", values="score", sort=False)
        failed = part.pivot_table(index="run", columns="job", values="diverged", aggfunc="any", sort=False)
        means = wide.where(~failed.astype(bool)).mean()
        if np.ptp(means.to_numpy()) == 0.0:
            continue  # the estimator does not depend on the swept parameters (the EKF, a fixed baseline)
        best = int(means.idxmin())
        for job in wide.columns:
            keep = ~(failed[job].astype(bool) | failed[best].astype(bool))
            diff = (wide[job] - wide[best])[keep].to_numpy()
            diff = np.where(np.abs(diff) < ROUND_OFF * wide[best][keep].to_numpy(), 0.0, diff)
            mean, low, high = paired_interval(diff)
            cell = part[part["job"] == job].iloc[0]
            rows.append(
                {
                    "job": int(job),
                    **{key: cell[key] for key in params},
                    "estimator": keys[0],
                    "group": keys[1],
                    "runs": int(keep.sum()),
                    "score_mean": float(means[job]),
                    "best_job": best,
                    "diff_mean": mean,
                    "diff_ci_low": low,
                    "diff_ci_high": high,
                    "differs": bool(low > 0),
                }
            )
    return pd.DataFrame(rows)


def versus_best_counts(table: pd.DataFrame) -> pd.DataFrame:
    """Per estimator and state group of a :func:`versus_best` table: its cells and how many of them
    differ from their panel's best."""
    counts = table.groupby(["estimator", "group"], sort=False).agg(
        cells=("job", "size"), differ_from_best=("differs", "sum")
    )
    return counts.reset_index()


@dataclass(frozen=True)
class HeatMapStyle:
    """How a heat-map figure is drawn and stored: inches per subplot, resolution, whether the
    subplots of one panel (column) share one colour scale and colour bar (else each has its own),
    and, if set, the size of the colour palette the PNG is stored with (a palette PNG of a few
    flat colours is several times smaller than RGBA)."""

    subplot_size: tuple[float, float]
    dpi: int
    shared_scale: bool = False
    palette: int | None = None


FULL_STYLE = HeatMapStyle(subplot_size=(3.4, 2.8), dpi=90)
"""The full aggregate's heat maps: one colour bar per subplot."""
COMPACT_STYLE = HeatMapStyle(subplot_size=(2.3, 1.6), dpi=80, shared_scale=True, palette=128)
"""The compact aggregate's (:mod:`quadest.aggregate.compact`): a 1000-cell grid's figure of 5 κ ×
4 panels stays legible at about 750 × 700 pixels, one colour bar per panel."""


def _save_png(fig, path: Path, style: HeatMapStyle) -> None:
    """Save ``fig`` as PNG at the style's resolution, as a palette PNG if the style has one (fast
    octree quantisation keeps the rare red of the best cell's star, which median cut merges away;
    Pillow is matplotlib's own PNG writer)."""
    if style.palette is None:
        fig.savefig(path, dpi=style.dpi)
        return
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=style.dpi)
    image = Image.open(buffer).convert("RGB").quantize(colors=style.palette, method=Image.Quantize.FASTOCTREE)
    image.save(path, optimize=True)


def heat_maps(table: pd.DataFrame, params: list[str], out: Path, style: HeatMapStyle = FULL_STYLE) -> list[Path]:
    """One α × β heat map per estimator and state group (rows: κ; columns: panels), drawn in
    ``style``; a cell missing from the grid stays blank."""
    alpha, beta, kappa = (ut_parameter(params, name) for name in UT_PARAMETERS)
    if table.empty or not (alpha and beta):
        return []
    panel = [p for p in params if p.split(".")[-1] not in UT_PARAMETERS]
    alphas, betas = sorted(table[alpha].unique()), sorted(table[beta].unique())
    made = []
    for (est, group), part in table.groupby(["estimator", "group"], sort=False):
        kappas = sorted(part[kappa].unique()) if kappa else [None]
        panels = list(part[panel].drop_duplicates().itertuples(index=False)) if panel else [()]
        width, height = style.subplot_size
        fig, axes = plt.subplots(
            len(kappas),
            len(panels),
            figsize=(width * len(panels), height * len(kappas)),
            squeeze=False,
            layout="constrained" if style.shared_scale else None,
        )
        for c, values in enumerate(panels):
            sel = part
            for key, value in zip(panel, values, strict=True):
                sel = sel[sel[key] == value]
            limits = {"vmin": sel["score_mean"].min(), "vmax": sel["score_mean"].max()} if style.shared_scale else {}
            title = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(panel, values, strict=True))
            for r, kv in enumerate(kappas):
                cells = sel if kv is None else sel[sel[kappa] == kv]
                grid = cells.pivot_table(index=beta, columns=alpha, values="score_mean").reindex(
                    index=betas, columns=alphas
                )
                differs = cells.pivot_table(index=beta, columns=alpha, values="differs", aggfunc="any")
                is_best = cells.assign(b=cells["job"] == cells["best_job"]).pivot_table(
                    index=beta, columns=alpha, values="b", aggfunc="any"
                )
                ax = axes[r, c]
                im = ax.imshow(grid.to_numpy(), aspect="auto", origin="lower", cmap="viridis", **limits)
                ys, xs = np.nonzero(differs.reindex_like(grid).fillna(False).to_numpy().astype(bool))
                ax.plot(xs, ys, "w.", ms=4)
                ys, xs = np.nonzero(is_best.reindex_like(grid).fillna(False).to_numpy().astype(bool))
                ax.plot(xs, ys, "r*", ms=8)
                ax.set_xticks(range(grid.shape[1]), [f"{a:g}" for a in grid.columns], fontsize=6, rotation=90)
                ax.set_yticks(range(grid.shape[0]), [f"{b:g}" for b in grid.index], fontsize=6)
                kappa_label = f"κ={kv:g}" if kv is not None else ""
                if not style.shared_scale:
                    ax.set_xlabel("α", fontsize=8)
                    ax.set_ylabel("β", fontsize=8)
                    ax.set_title(title + (f", {kappa_label}" if kappa_label else ""), fontsize=7)
                    fig.colorbar(im, ax=ax)
                    continue
                if r == 0:
                    ax.set_title(title, fontsize=7)
                if r == len(kappas) - 1:
                    ax.set_xlabel("α", fontsize=7)
                else:
                    ax.tick_params(labelbottom=False)
                if c == 0:
                    ax.set_ylabel(f"{kappa_label}\nβ" if kappa_label else "β", fontsize=7)
            if style.shared_scale:
                bar = fig.colorbar(im, ax=axes[:, c].tolist(), location="bottom", shrink=0.9, aspect=25)
                bar.ax.tick_params(labelsize=6)
        fig.suptitle(f"{est}, {group}: mean RMSE; • differs from ★ (paired 95 % CI)", fontsize=9)
        if not style.shared_scale:
            fig.tight_layout()
        path = out / f"versus_best_{est}_{group.replace(' ', '_')}.png"
        _save_png(fig, path, style)
        plt.close(fig)
        made.append(path)
    return made
