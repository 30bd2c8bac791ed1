"""RMSE against particle count and against time per step, for a job that runs particle filters at
several particle counts (``experiment=seed001_rates``).

``python -m quadest.aggregate.particle_count JOB_DIR`` reads the job's ``metrics.csv`` and writes
``JOB_DIR/figures/rmse_vs_particles.png`` and the series it plots, ``JOB_DIR/rmse_vs_particles.csv``.

A *family* is an estimator label without its particle-count suffix (``ekpf_200`` → ``ekpf``, with
200 from the ``particles`` column), so one line joins a filter's counts. An estimator without
particles (the EKF) is a reference: a horizontal line in the count panel, one point in the time
panel. The RMSE of a run is its per-state RMSE averaged over the states (diverged runs left out);
each point is the mean over runs with its 95 % Student-t interval; the time is the job's
``step_time_us`` (one step of one run).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.ticker import NullFormatter

from quadest.aggregate.job_cli import read_job_metrics
from quadest.aggregate.statistics import with_confidence_interval

FIGURE = "rmse_vs_particles.png"
SERIES = "rmse_vs_particles.csv"


def family_of(estimator: str, particles: float) -> str:
    """The label without its ``_<particles>`` suffix (the label itself without particles)."""
    if np.isnan(particles):
        return estimator
    return estimator.removesuffix(f"_{int(particles)}")


def particle_count_series(metrics: pd.DataFrame) -> pd.DataFrame:
    """One row per estimator of ``metrics`` (the job's ``metrics.csv``, quantity ``filter``):
    ``estimator``, ``family``, ``particles`` (NaN: a reference), ``runs``, ``rmse_mean``,
    ``rmse_std``, ``ci95_low``, ``ci95_high`` and ``step_time_us``, sorted by family and count."""
    rows = metrics[(metrics["quantity"] == "filter") & ~metrics["diverged"].astype(bool)]
    per_run = rows.groupby(["estimator", "run"], sort=False)["rmse"].mean().reset_index()
    stats = per_run.groupby("estimator", sort=False)["rmse"].agg(rmse_mean="mean", rmse_std="std", runs="count")
    info = metrics.groupby("estimator", sort=False)[["particles", "step_time_us"]].first()
    out = with_confidence_interval(stats.join(info).reset_index())
    out["family"] = [family_of(e, p) for e, p in zip(out["estimator"], out["particles"], strict=True)]
    columns = ["estimator", "family", "particles", "runs", "rmse_mean", "rmse_std", "ci95_low", "ci95_high"]
    return out[[*columns, "step_time_us"]].sort_values(["family", "particles"], ignore_index=True)


def plot_particle_count(series: pd.DataFrame, path: Path, title: str = "") -> plt.Figure:
    """Two panels from :func:`particle_count_series`: RMSE against particle count (references as
    horizontal lines) and against time per step (references as single points), 95 % intervals as
    error bars. Saves the figure to ``path`` and returns it (open, for inspection)."""
    fig, (by_count, by_time) = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for i, (family, s) in enumerate(series.groupby("family", sort=False)):
        colour = f"C{i}"
        rmse = s["rmse_mean"].to_numpy(float)
        yerr = np.array([rmse - s["ci95_low"].to_numpy(float), s["ci95_high"].to_numpy(float) - rmse])
        time_us = s["step_time_us"].to_numpy(float)
        if s["particles"].isna().all():
            by_count.axhline(rmse[0], color=colour, ls="--", label=family)
            by_time.errorbar(time_us, rmse, yerr=yerr, color=colour, marker="s", ls="none", label=family)
            continue
        for ax, x in ((by_count, s["particles"].to_numpy(float)), (by_time, time_us)):
            ax.errorbar(x, rmse, yerr=yerr, color=colour, marker="o", ms=4, capsize=2, label=family)
    by_count.set(xscale="log", xlabel="particles per run", ylabel="RMSE (mean over runs, 95 % CI)")
    by_time.set(xscale="log", xlabel="time per step and run (µs)")
    counts = series["particles"].dropna().unique()
    by_count.set_xticks(counts, [f"{int(c)}" for c in counts])
    by_count.xaxis.set_minor_formatter(NullFormatter())
    by_count.legend(fontsize=8)
    for ax in (by_count, by_time):
        ax.grid(alpha=0.3, which="both")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return fig


def main(argv: list[str] | None = None) -> int:
    job = read_job_metrics(
        "particle_count", "RMSE against particle count and time per step for a job's particle filters.", argv
    )
    if job is None:
        return 2
    job_dir, metrics = job
    if "particles" not in metrics.columns:
        print(f"particle_count: error: {job_dir / 'metrics.csv'} has no particle filters (no 'particles' column)",
              file=sys.stderr)  # fmt: skip
        return 2
    series = particle_count_series(metrics)
    series.to_csv(job_dir / SERIES, index=False)
    runs = int(series["runs"].max())
    fig = plot_particle_count(series, job_dir / "figures" / FIGURE, f"{job_dir.name}: {runs} runs")
    plt.close(fig)
    print(f"Wrote {job_dir / 'figures' / FIGURE} and {job_dir / SERIES}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
