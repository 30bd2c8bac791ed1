"""The compact aggregate of a large grid (``hydra.callbacks.aggregate.output: compact``).

The full aggregate of a 1000-cell UT grid is tens of MB (one row per job × estimator × state in
``cells.csv``, every cell's paired comparison in ``paired.csv``, every table again in
``report.md``). The compact one keeps what a reader of the grid needs, at one row per cell:

- ``cells_compact.csv``: per cell (job) its status and swept values; per estimator its diverged
  runs (``<estimator>.diverged``); per estimator that takes the swept parameters and state group
  (velocities, angle rates, angles, positions) the group's RMSE (``<estimator>.<group>.rmse_mean``:
  the mean over the runs that did not diverge of the run's mean RMSE over the group's filter
  states, the score of :mod:`quadest.aggregate.versus_best`) and, in a sweep over α, the paired
  difference to the best cell of the panel (``diff_mean``, ``diff_ci_low``, ``diff_ci_high``: 95 %
  CI) and ``differs``. Numbers are written to 6 significant digits.
- ``versus_best_panels``: per estimator, state group and panel (a setting of the swept values
  other than α, β, κ: the sensor level) the best cell, how many cells differ from it, and the
  group RMSE of each estimator that does not take the swept parameters (the EKF, a UKF at its
  defaults: run once per panel through the result cache), for comparison;
- ``versus_best_counts``: per estimator and state group, the cells that differ from their panel's
  best (the full aggregate's table);
- ``timing``: the wall time of the sweep and each estimator's time per step and run;
- the heat maps of :func:`quadest.aggregate.versus_best.heat_maps` in the compact style (one colour
  scale per panel, a palette PNG), the cost–accuracy figure
  (:func:`quadest.aggregate.figures.cost_accuracy`); and ``report.md``, which lists and links these.

It does not write ``cells.csv``, ``paired.csv``, ``jobs.csv``, the ``rmse``/``divergence``/
``paired_summary`` tables or the other figures; ``quadest-aggregate SWEEP_DIR --output full``
makes them from the job folders. In a sweep without α every estimator's group RMSE is a column
of the cell table and there are no versus-best files.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from quadest.aggregate.figures import cost_accuracy
from quadest.aggregate.statistics import timing_table
from quadest.aggregate.versus_best import (
    COMPACT_STYLE,
    UT_PARAMETERS,
    heat_maps,
    run_scores,
    ut_parameter,
    versus_best,
    versus_best_counts,
)
from quadest.evaluation.formatting import markdown_table

CELL_TABLE = "cells_compact.csv"
FLOAT_FORMAT = "%.6g"
"""Significant digits of the compact tables: far below the 95 % CIs of 50 runs."""
VERSUS_BEST_COLUMNS = {
    "score_mean": "rmse_mean",
    "diff_mean": "diff_mean",
    "diff_ci_low": "diff_ci_low",
    "diff_ci_high": "diff_ci_high",
    "differs": "differs",
}
"""Columns of the versus-best table kept per estimator and group, and their names in the cell table."""


def _column(estimator: str, group: str, field: str) -> str:
    """``srukf.angle_rates.rmse_mean``: a cell-table column of one estimator and state group."""
    return f"{estimator}.{group.replace(' ', '_')}.{field}"


def group_means(scores: pd.DataFrame) -> pd.DataFrame:
    """Per job, estimator and state group: the mean score over the runs that did not diverge (as
    :func:`~quadest.aggregate.versus_best.versus_best` computes it), column ``rmse_mean``."""
    kept = scores[~scores["diverged"].astype(bool)]
    return kept.groupby(["job", "estimator", "group"], sort=False)["score"].mean().rename("rmse_mean").reset_index()


def cell_table(
    jobs: pd.DataFrame, cells: pd.DataFrame, means: pd.DataFrame, against_best: pd.DataFrame, params: list[str]
) -> pd.DataFrame:
    """One row per job of the grid (see the module docstring); ``cells`` is the tidy table of
    :func:`~quadest.aggregate.sweep.load_sweep`, ``means`` :func:`group_means`, ``against_best`` the
    versus-best table (empty when the sweep is not over α)."""
    table = jobs[["job", "status", *params]].set_index("job")
    if not cells.empty:
        filt = cells[cells["quantity"] == "filter"]
        diverged = filt.groupby(["job", "estimator"], sort=False)["diverged"].max().unstack("estimator")
        table = table.join(diverged.rename(columns=lambda est: f"{est}.diverged"))
    rows = means
    if not against_best.empty:
        rows = against_best[["job", "estimator", "group", *VERSUS_BEST_COLUMNS]].rename(columns=VERSUS_BEST_COLUMNS)
    for (est, group), part in rows.groupby(["estimator", "group"], sort=False):
        fields = part.drop(columns=["estimator", "group"]).set_index("job")
        table = table.join(fields.rename(columns=lambda field, e=est, g=group: _column(e, g, field)))
    return table.reset_index()


def panel_table(means: pd.DataFrame, against_best: pd.DataFrame, params: list[str]) -> pd.DataFrame:
    """Per estimator, state group and panel of the versus-best table: the best cell (job, swept
    values, group RMSE), the number of cells and of those that differ from it, and the group RMSE
    of every estimator left out of the table (one that does not take the swept parameters: its
    cells in a panel agree, their mean is shown)."""
    panel = [p for p in params if p.split(".")[-1] not in UT_PARAMETERS]
    ut = [p for p in params if p.split(".")[-1] in UT_PARAMETERS]
    baselines = means[~means["estimator"].isin(set(against_best["estimator"]))]
    rows = []
    for keys, part in against_best.groupby(["estimator", "group", *panel], sort=False, dropna=False):
        best = part[part["job"] == part["best_job"]].iloc[0]
        row = {
            "estimator": keys[0],
            "group": keys[1],
            **{key: best[key] for key in panel},
            "cells": len(part),
            "differ_from_best": int(part["differs"].sum()),
            "best_job": int(best["job"]),
            **{f"best {key}": best[key] for key in ut},
            "best rmse_mean": best["score_mean"],
        }
        same = baselines[baselines["job"].isin(part["job"]) & (baselines["group"] == keys[1])]
        for est, values in same.groupby("estimator", sort=False):
            row[f"{est} rmse_mean"] = values["rmse_mean"].mean()
        rows.append(row)
    return pd.DataFrame(rows)


def _markdown(frame: pd.DataFrame) -> str:
    """``frame`` as Markdown, its numbers to the digits of :data:`FLOAT_FORMAT`."""
    return markdown_table(frame.map(lambda v: FLOAT_FORMAT % v if isinstance(v, float) else v))


def _write(frame: pd.DataFrame, out: Path, name: str) -> dict[str, str]:
    """``name.csv`` and ``name.md`` of a small table; the report's entry for it."""
    frame.to_csv(out / f"{name}.csv", index=False, float_format=FLOAT_FORMAT)
    md = _markdown(frame)
    (out / f"{name}.md").write_text(md)
    return {"name": name, "md": md}


def write_compact(
    sweep_dir: Path, out: Path, cells: pd.DataFrame, jobs: pd.DataFrame, params: list[str], wall_time: float | None
) -> tuple[list[dict[str, str]], list[Path]]:
    """Write the compact aggregate of ``sweep_dir`` into ``out``; returns the report's tables
    (``{"name", "md"}``) and the figures written."""
    scores = run_scores(sweep_dir, jobs, params)
    means = group_means(scores) if not scores.empty else pd.DataFrame(columns=["job", "estimator", "group"])
    against_best = pd.DataFrame()
    if ut_parameter(params, "alpha") and not scores.empty:
        against_best = versus_best(scores, params)
    cell_table(jobs, cells, means, against_best, params).to_csv(
        out / CELL_TABLE, index=False, float_format=FLOAT_FORMAT
    )
    written, made = [], []
    if not against_best.empty:
        written.append(_write(panel_table(means, against_best, params), out, "versus_best_panels"))
        written.append(_write(versus_best_counts(against_best), out, "versus_best_counts"))
        (out / "figures").mkdir(exist_ok=True)
        made = heat_maps(against_best, params, out / "figures", style=COMPACT_STYLE)
    if not cells.empty:
        timing = timing_table(cells)
        timing.to_csv(out / "timing.csv", index=False, float_format=FLOAT_FORMAT)
        wall = "not measured (aggregated by hand)" if wall_time is None else f"{wall_time:.0f} s"
        md = f"Wall time of the sweep: {wall}.\n\n{_markdown(timing)}"
        (out / "timing.md").write_text(md)
        written.append({"name": "timing", "md": md})
        (out / "figures").mkdir(exist_ok=True)
        made = [*made, *cost_accuracy(cells, out / "figures" / "cost_accuracy")]
    return written, made
