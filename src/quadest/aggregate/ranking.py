"""Seed 004's ranking (HHCF > HF > HCKF > EKF, its §4.2) tested on a job or a sweep of
``experiment=seed004_landing`` (docs/seed004-landing.md), and the time per step of its filters.

Ranking. Per run, the 3-D position and velocity RMSE (root of the sum of the three axes' mean
squares) and the attitude error angle's RMSE (``error_angle``), then the job's own paired
comparison (:func:`quadest.evaluation.paired.paired_comparison` on these three grouped states: paired
Student-t and Fieller CIs, Wilcoxon, Holm over every pair of the job's estimators × the three states) for each
step of :data:`STEPS`. A step *holds* when its Holm-corrected Wilcoxon p is below 0.05 and the
better-ranked filter has the smaller RMSE, is *reversed* when p < 0.05 the other way, and is
*not shown* otherwise.

Time per step. Each job measures one ``step_time_us`` per estimator (its batch's wall time per
step and run). For each pair of :data:`TIME_PAIRS` the ratio of the two in every job of a sweep
is a paired sample; the table gives the geometric mean of the ratios over the jobs with the 95 %
Student-t interval of the mean log ratio (jobs independent), as ``rel_diff = ratio − 1`` and its
``rel_ci_low``/``rel_ci_high``. One job gives the ratio without an interval.

``python -m quadest.aggregate.ranking DIR`` on a job folder (holds ``metrics.csv``) writes
``DIR/ranking.md``, ``DIR/paired_grouped.csv`` (the grouped paired comparison, every pair) and
``DIR/step_time.csv``; on a sweep folder (numbered job folders) it writes the same three files,
one block or row group per job with the sweep's parameters, into ``DIR/aggregate/``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from quadest.aggregate.sweep import load_sweep
from quadest.evaluation.paired import CONFIDENCE, paired_comparison

GROUPS = {"position_3d": ("x", "y", "z"), "velocity_3d": ("vx", "vy", "vz")}
STEPS = (
    ("hhcf", "hf"), ("hf", "hckf"), ("hckf", "mekf"),  # seed 004's ranking, step by step
    ("hhcf", "hckf"), ("hf", "mekf"), ("huber_ckf", "ckf"),  # the Huber update against its parent
    ("hckf", "ckf"), ("hhcf", "huber_ckf"),  # the fifth-degree rule against the third-degree one
)  # fmt: skip
TIME_PAIRS = (("hhcf", "hckf"), ("huber_ckf", "ckf"), ("hf", "mekf"), ("hckf", "ckf"))
TIME_COLUMNS = (
    "estimator", "reference", "jobs", "step_time_us", "reference_step_time_us",
    "ratio", "ratio_ci_low", "ratio_ci_high", "rel_diff", "rel_ci_low", "rel_ci_high",
)  # fmt: skip


def has_grouped_states(metrics: pd.DataFrame) -> bool:
    """Whether ``metrics`` holds every state :func:`grouped_metrics` reads (a job of ``model=ins``)."""
    return {*(axis for axes in GROUPS.values() for axis in axes), "error_angle"} <= set(metrics["state"])


def grouped_metrics(metrics: pd.DataFrame) -> pd.DataFrame:
    """One row per estimator × run × {position_3d, velocity_3d, error_angle}; a diverged run
    keeps its row (RMSE NaN, ``diverged`` true), so that every estimator has every run and the
    paired comparison can leave the run out of each pair it diverged in."""
    keep = ["estimator", "run", "diverged"]
    wide = metrics.pivot_table(index=["estimator", "run"], columns="state", values="rmse", sort=False, dropna=False)
    diverged = metrics.groupby(["estimator", "run"], sort=False)["diverged"].any()
    rows = []
    for state, axes in GROUPS.items():
        rows.append(pd.DataFrame({"state": state, "rmse": np.sqrt((wide[list(axes)] ** 2).sum(axis=1))}))
    rows.append(pd.DataFrame({"state": "error_angle", "rmse": wide["error_angle"]}))
    out = pd.concat(rows).reset_index().merge(diverged.reset_index(), on=["estimator", "run"])
    out["unit"] = out["state"].map({"position_3d": "m", "velocity_3d": "m/s", "error_angle": "deg"})
    out["quantity"] = "filter"
    return out[keep[:2] + ["state", "unit", "quantity", "rmse", "diverged"]]


def grouped_paired(metrics: pd.DataFrame) -> pd.DataFrame:
    """The paired comparison (every pair of the job's estimators, in the job's order) of the grouped
    states of :func:`grouped_metrics`, with Holm over its rows."""
    return paired_comparison(grouped_metrics(metrics))


def ranking_lines(metrics: pd.DataFrame, table: pd.DataFrame | None = None) -> list[str]:
    """The Markdown table of every step of :data:`STEPS` whose two estimators are in ``metrics``
    (a job's ``metrics.csv``), one row per step and grouped state; ``table``: its
    :func:`grouped_paired` if already computed."""
    names = list(dict.fromkeys(metrics["estimator"]))
    table = grouped_paired(metrics) if table is None else table
    lines = [
        "| claim | state | runs | better − worse, % of the earlier estimator's RMSE (95 % CI) "
        "| p Wilcoxon (Holm) | holds? |",
        "|---|---|---|---|---|---|",
    ]
    for better, worse in STEPS:
        if better not in names or worse not in names:
            continue
        ref, est = sorted((better, worse), key=names.index)
        sign = 1.0 if est == better else -1.0
        for _, r in table[(table["estimator"] == est) & (table["reference"] == ref)].iterrows():
            rel, lo, hi = (sign * 100 * r[c] for c in ("rel_diff", "rel_ci_low", "rel_ci_high"))
            lo, hi = min(lo, hi), max(lo, hi)
            p = r["p_wilcoxon_holm"]
            verdict = "not shown" if not p < 0.05 else ("yes" if rel < 0 else "no (reversed)")
            claim = f"| {better} > {worse} | {r['state']} | {r['runs']} |"
            lines.append(f"{claim} {rel:+.2f} % [{lo:+.2f}, {hi:+.2f}] | {p:.2g} | {verdict} |")
    return lines


def step_time_ratios(times: pd.DataFrame) -> pd.DataFrame:
    """Per pair of :data:`TIME_PAIRS` present, the step-time ratio over jobs (module docstring);
    ``times``: columns ``job``, ``estimator``, ``step_time_us`` (one row per job and estimator)."""
    wide = times.pivot_table(index="job", columns="estimator", values="step_time_us")
    rows = []
    for est, ref in TIME_PAIRS:
        if est not in wide or ref not in wide:
            continue
        pair = wide[[est, ref]].dropna()
        logs = np.log(pair[est].to_numpy() / pair[ref].to_numpy())
        n = logs.size
        half = stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1) * logs.std(ddof=1) / np.sqrt(n) if n >= 2 else np.nan
        ratio, low, high = np.exp(logs.mean()), np.exp(logs.mean() - half), np.exp(logs.mean() + half)
        rows.append(
            {
                "estimator": est, "reference": ref, "jobs": n, "step_time_us": float(np.exp(np.log(pair[est]).mean())),
                "reference_step_time_us": float(np.exp(np.log(pair[ref]).mean())),
                "ratio": ratio, "ratio_ci_low": low, "ratio_ci_high": high,
                "rel_diff": ratio - 1.0, "rel_ci_low": low - 1.0, "rel_ci_high": high - 1.0,
            }
        )  # fmt: skip
    return pd.DataFrame(rows, columns=list(TIME_COLUMNS))


def _step_times(metrics: pd.DataFrame, job: int) -> pd.DataFrame:
    times = metrics.groupby("estimator", sort=False)["step_time_us"].first().reset_index()
    return times.assign(job=job)


def _time_lines(ratios: pd.DataFrame) -> list[str]:
    lines = ["", "| time per step | jobs | µs per step and run | ratio (95 % CI) |", "|---|---|---|---|"]
    for _, r in ratios.iterrows():
        ci = f" [{r['ratio_ci_low']:.3f}, {r['ratio_ci_high']:.3f}]" if r["jobs"] >= 2 else ""
        times = f"{r['step_time_us']:.0f} / {r['reference_step_time_us']:.0f}"
        lines.append(f"| {r['estimator']} / {r['reference']} | {r['jobs']} | {times} | {r['ratio']:.3f}{ci} |")
    return lines


def rank_job(job_dir: Path) -> list[str]:
    """Write the job's ``ranking.md``, ``paired_grouped.csv`` and ``step_time.csv``; the lines."""
    metrics = pd.read_csv(job_dir / "metrics.csv")
    table = grouped_paired(metrics)
    ratios = step_time_ratios(_step_times(metrics, 0))
    lines = ranking_lines(metrics, table) + _time_lines(ratios)
    table.to_csv(job_dir / "paired_grouped.csv", index=False)
    ratios.to_csv(job_dir / "step_time.csv", index=False)
    (job_dir / "ranking.md").write_text("\n".join(lines) + "\n")
    return lines


def rank_sweep(sweep_dir: Path) -> list[str]:
    """Rank every finished job of a sweep; write the three files into ``sweep_dir/aggregate``."""
    _, jobs, params = load_sweep(sweep_dir)
    tables, times, lines = [], [], []
    for _, job in jobs[jobs["status"] == "ok"].sort_values("job").iterrows():
        metrics = pd.read_csv(sweep_dir / str(int(job["job"])) / "metrics.csv")
        table = grouped_paired(metrics)
        cell = {key: job[key] for key in params}
        tables.append(table.assign(job=int(job["job"]), **cell))
        times.append(_step_times(metrics, int(job["job"])))
        title = ", ".join(f"{key} = {value}" for key, value in cell.items())
        lines += [f"## Job {int(job['job'])}: {title}", "", *ranking_lines(metrics, table), ""]
    ratios = step_time_ratios(pd.concat(times, ignore_index=True))
    lines += ["## Time per step over the jobs", *_time_lines(ratios)]
    out = sweep_dir / "aggregate"
    out.mkdir(exist_ok=True)
    paired = pd.concat(tables, ignore_index=True)
    paired[["job", *params, *(c for c in paired.columns if c not in ("job", *params))]].to_csv(
        out / "paired_grouped.csv", index=False
    )
    ratios.to_csv(out / "step_time.csv", index=False)
    (out / "ranking.md").write_text("\n".join(lines) + "\n")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m quadest.aggregate.ranking",
        description="Seed 004's ranking (HHCF > HF > HCKF > EKF) and step-time ratios of a job or a sweep.",
    )
    parser.add_argument("dir", type=Path, help="a job folder (holds metrics.csv) or a sweep folder (numbered jobs)")
    folder = parser.parse_args(argv).dir
    if (folder / "metrics.csv").is_file():
        lines = rank_job(folder)
    elif folder.is_dir() and any(p.name.isdigit() and (p / "metrics.csv").is_file() for p in folder.iterdir()):
        lines = rank_sweep(folder)
    else:
        print(f"ranking: error: {folder} holds neither metrics.csv nor numbered job folders", file=sys.stderr)
        return 2
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
