"""RMSE against particle count and against time per step, for a job that runs particle filters at
several particle counts (``experiment=seed001_rates``), seed 001's "filtering efficiency" read both
ways, and the trend over a sweep of the process noise.

``python -m quadest.aggregate.particle_count JOB_DIR`` reads the job's ``metrics.csv`` and writes
``JOB_DIR/figures/rmse_vs_particles.png``, the series it plots, ``JOB_DIR/rmse_vs_particles.csv``, and
``JOB_DIR/efficiency.csv`` (:func:`efficiency_table`).
``python -m quadest.aggregate.particle_count --sweep SWEEP_DIR`` reads every job of a sweep over
``model.Q`` (``experiments/sweep_seed001_q.yaml``) and writes ``SWEEP_DIR/noise_trend.csv``
(:func:`noise_trend`), ``SWEEP_DIR/noise_change.csv`` (:func:`noise_change`) and
``SWEEP_DIR/time_efficiency.csv`` (:func:`time_efficiency`).

Seed 001 (Li & Liang 2015, §3.1, eq. 10, lost from the seed text) says only that the particle
count N enters the efficiency and that ILOPF's is about 20 % higher than EKPF's. Two readings, both
ours: *error-based*, ``η = 1 / (N · RMSE)``, so at equal N the ratio ``η_ILOPF / η_EKPF`` is
``RMSE_EKPF / RMSE_ILOPF`` (independent of timings and of the constant in front), and
*time-based*, accuracy per unit of computing time, ``η_t = 1 / (RMSE · t_step)``, so the ratio is
the error ratio times ``t_EKPF / t_ILOPF``. "20 % higher" is then a ratio of 1.2 (our reading).

A *family* is an estimator label without its particle-count suffix (``ekpf_200`` → ``ekpf``, with
200 from the ``particles`` column), so one line joins a filter's counts. An estimator without
particles (the EKF) is a reference: a horizontal line in the count panel, one point in the time
panel. The RMSE of a run is its per-state RMSE averaged over the states (diverged runs left out);
each point is the mean over runs with its 95 % Student-t interval; the time is the job's
``step_time_us`` (one step of one run).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import yaml
from matplotlib.ticker import NullFormatter
from scipy import stats

from quadest.aggregate.job_cli import read_job_metrics
from quadest.aggregate.statistics import with_confidence_interval
from quadest.evaluation.intervals import fieller_interval, mean_and_half_width

FIGURE = "rmse_vs_particles.png"
SERIES = "rmse_vs_particles.csv"
EFFICIENCY = "efficiency.csv"
NOISE_TREND = "noise_trend.csv"
NOISE_CHANGE = "noise_change.csv"
TIME_EFFICIENCY = "time_efficiency.csv"
EFFICIENCY_PAIRS = (("ilopf", "ekpf"), ("ilopf_uniform", "ekpf"))
"""(family, reference family) compared at equal particle count: seed 001's ILOPF against its EKPF."""
Job = tuple[float, pd.DataFrame, pd.DataFrame]
"""One job of a sweep over ``model.Q``: ``(Q, metrics.csv, rmse_summary.csv)``."""


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


def per_run_rmse(metrics: pd.DataFrame) -> pd.DataFrame:
    """Run × estimator table of the per-run RMSE averaged over the filter states (NaN where the
    run diverged), from a job's tidy ``metrics.csv``."""
    rows = metrics[metrics["quantity"] == "filter"]
    rmse = rows["rmse"].where(~rows["diverged"].astype(bool))
    wide = rows.assign(rmse=rmse).groupby(["run", "estimator"], sort=False)["rmse"].mean(numeric_only=False)
    return wide.unstack("estimator")


def ratio_interval(numerator: np.ndarray, denominator: np.ndarray, confidence: float) -> tuple[float, float, float]:
    """``mean(numerator) / mean(denominator)`` of paired per-run values and its Fieller interval
    (:mod:`quadest.evaluation.intervals`; NaN ends if unbounded)."""
    ratio, low, high = (
        float(v[0]) for v in fieller_interval(numerator[:, None], denominator[:, None], 1.0 - confidence)
    )
    return ratio, low, high


def diff_interval(
    after: np.ndarray, before: np.ndarray, confidence: float
) -> tuple[float, float, float, float, float, float]:
    """Mean paired difference ``after − before``, its relative size ``/ mean(before)`` and the
    intervals of both: Student's t of the difference, Fieller's of the ratio
    (:mod:`quadest.evaluation.intervals`)."""
    d, half = (float(v[0]) for v in mean_and_half_width((after - before)[:, None], 1.0 - confidence))
    rel, rel_low, rel_high = ratio_interval(after - before, before, confidence)
    return d, d - half, d + half, rel, rel_low, rel_high


def _particle_counts(series: pd.DataFrame, family: str) -> dict[int, str]:
    s = series[series["family"] == family]
    return {int(p): e for p, e in zip(s["particles"], s["estimator"], strict=True)}


def efficiency_table(metrics: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """Seed 001's efficiency ratio of each pair of :data:`EFFICIENCY_PAIRS` at every particle
    count both families have: ``error_ratio = mean RMSE_ref / mean RMSE_est`` (error-based
    ``η_est / η_ref``) over the runs that diverged in neither, with its paired Student-t interval
    at ``confidence``; the job's times per step and ``time_ratio = t_ref / t_est``;
    ``time_efficiency_ratio`` = their product (time-based ``η_t,est / η_t,ref``; one timing per
    job, so no interval here: :func:`time_efficiency` has one over the jobs of a sweep)."""
    series = particle_count_series(metrics)
    wide = per_run_rmse(metrics)
    times = metrics.groupby("estimator", sort=False)["step_time_us"].first()
    rows = []
    for family, ref_family in EFFICIENCY_PAIRS:
        est_by_n, ref_by_n = _particle_counts(series, family), _particle_counts(series, ref_family)
        for n in sorted(set(est_by_n) & set(ref_by_n)):
            est, ref = est_by_n[n], ref_by_n[n]
            usable = wide[est].notna() & wide[ref].notna()
            a, b = wide.loc[usable, est].to_numpy(float), wide.loc[usable, ref].to_numpy(float)
            ratio, low, high = ratio_interval(b, a, confidence)
            time_ratio = float(times[ref] / times[est])
            rows.append(
                {
                    "estimator": est, "reference": ref, "family": family, "particles": n, "runs": a.size,
                    "rmse_mean": a.mean(), "reference_rmse_mean": b.mean(),
                    "error_ratio": ratio, "error_ci_low": low, "error_ci_high": high,
                    "step_time_us": float(times[est]), "reference_step_time_us": float(times[ref]),
                    "time_ratio": time_ratio, "time_efficiency_ratio": ratio * time_ratio,
                }
            )  # fmt: skip
    return pd.DataFrame(rows)


def read_sweep(sweep_dir: Path) -> list[Job]:
    """``(Q, metrics, rmse_summary)`` of every job folder of a sweep over ``model.Q``,
    sorted by Q (a job is a sub-folder with ``metrics.csv`` and ``config.yaml``)."""
    jobs = []
    for job in sorted(p for p in sweep_dir.iterdir() if (p / "metrics.csv").is_file()):
        record = yaml.safe_load((job / "config.yaml").read_text())
        summary = pd.read_csv(job / "rmse_summary.csv")
        jobs.append((float(record["model"]["Q"]), pd.read_csv(job / "metrics.csv"), summary))
    return sorted(jobs, key=lambda j: j[0])


def noise_trend(jobs: list[Job]) -> pd.DataFrame:
    """One row per Q and estimator: the mean over runs of the per-run RMSE averaged over the
    filter states with its 95 % Student-t interval (:func:`particle_count_series`), the pooled
    RMSE over runs and states ``√(mean MSE)`` and the PCRLB floor under it ``√(mean bound)``
    (``rmse_summary.csv``: the truth follows the filter model, so pooled ≥ floor up to Monte
    Carlo error)."""
    frames = []
    for q, metrics, summary in jobs:
        series = particle_count_series(metrics)
        rows = summary[summary["quantity"] == "filter"]
        pooled = rows.groupby("estimator", sort=False)["mse_mean"].mean().pow(0.5).rename("pooled_rmse")
        floor = rows.groupby("estimator", sort=False)["pcrlb"].apply(lambda v: float(np.sqrt(np.mean(v**2))))
        frames.append(series.join(pooled, on="estimator").join(floor.rename("pcrlb"), on="estimator").assign(Q=q))
    out = pd.concat(frames, ignore_index=True)
    return out[["Q", *[c for c in out.columns if c != "Q"]]]


def noise_change(jobs: list[Job], confidence: float = 0.95) -> pd.DataFrame:
    """Per estimator, the change of its per-run RMSE (averaged over the filter states) from the
    smallest to the largest Q of the sweep: the same seed gives every job the same runs and the
    same standard-normal draws (the process noise is scaled by √Q), so the runs are paired; the
    mean difference and its relative size with paired Student-t intervals (:func:`diff_interval`)."""
    (q_low, low_metrics, _), (q_high, high_metrics, _) = jobs[0], jobs[-1]
    low, high = per_run_rmse(low_metrics), per_run_rmse(high_metrics)
    rows = []
    for est in low.columns:
        usable = low[est].notna() & high[est].notna()
        a, b = high.loc[usable, est].to_numpy(float), low.loc[usable, est].to_numpy(float)
        d, lo, hi, rel, rlo, rhi = diff_interval(a, b, confidence)
        rows.append(
            {
                "estimator": est, "Q_low": q_low, "Q_high": q_high, "runs": a.size,
                "rmse_low": b.mean(), "rmse_high": a.mean(), "mean_diff": d, "ci_low": lo, "ci_high": hi,
                "rel_diff": rel, "rel_ci_low": rlo, "rel_ci_high": rhi,
            }
        )  # fmt: skip
    return pd.DataFrame(rows)


def time_efficiency(jobs: list[Job], confidence: float = 0.95) -> pd.DataFrame:
    """Time-based efficiency with an interval. The time ratio ``t_ref / t_est`` of each pair at
    equal N is measured once per job; the jobs whose estimators were computed (not handed over by
    the result cache) are independent timings, so its mean and Student-t interval come from them.
    Per job, the error ratio and its interval (:func:`efficiency_table`); the product
    of the two estimates is the time-based ratio ``η_t,est / η_t,ref``, and the product of the two
    intervals, each at level ``1 − (1 − confidence)/2``, covers it with probability at least
    ``confidence`` (Bonferroni)."""
    each = 1.0 - (1.0 - confidence) / 2.0
    tables = [(q, efficiency_table(metrics, each)) for q, metrics, _ in jobs]
    fresh = [
        table
        for (_, table), (_, metrics, _) in zip(tables, jobs, strict=True)
        if not metrics["from_cache"].astype(bool).any()
    ]
    timings = pd.concat(fresh).groupby(["estimator", "reference"])["time_ratio"].agg(["mean", "std", "count"])
    t = stats.t.ppf(1.0 - (1.0 - each) / 2.0, timings["count"] - 1)
    half = t * timings["std"] / np.sqrt(timings["count"])
    timings = timings.assign(time_ci_low=timings["mean"] - half, time_ci_high=timings["mean"] + half)
    rows = []
    for q, table in tables:
        for row in table.itertuples(index=False):
            tr = timings.loc[(row.estimator, row.reference)]
            rows.append(
                {
                    "Q": q, "estimator": row.estimator, "reference": row.reference, "particles": row.particles,
                    "error_ratio": row.error_ratio, "error_ci_low": row.error_ci_low,
                    "error_ci_high": row.error_ci_high, "timings": int(tr["count"]), "time_ratio": tr["mean"],
                    "time_ci_low": tr["time_ci_low"], "time_ci_high": tr["time_ci_high"],
                    "time_efficiency_ratio": row.error_ratio * tr["mean"],
                    "time_efficiency_ci_low": row.error_ci_low * tr["time_ci_low"],
                    "time_efficiency_ci_high": row.error_ci_high * tr["time_ci_high"],
                }
            )  # fmt: skip
    return pd.DataFrame(rows)


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


def sweep_main(sweep_dir: Path) -> int:
    """``--sweep``: the three tables of a sweep over ``model.Q``."""
    jobs = read_sweep(sweep_dir) if sweep_dir.is_dir() else []
    if len({q for q, *_ in jobs}) < 2:
        print(f"particle_count: error: {sweep_dir} holds no sweep over model.Q (job folders with metrics.csv "
              "and config.yaml at two or more Q)", file=sys.stderr)  # fmt: skip
        return 2
    for name, table in (
        (NOISE_TREND, noise_trend(jobs)), (NOISE_CHANGE, noise_change(jobs)), (TIME_EFFICIENCY, time_efficiency(jobs))
    ):  # fmt: skip
        table.to_csv(sweep_dir / name, index=False)
    print(f"Wrote {sweep_dir / NOISE_TREND}, {sweep_dir / NOISE_CHANGE} and {sweep_dir / TIME_EFFICIENCY}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] == "--sweep":
        parser = argparse.ArgumentParser(prog="python -m quadest.aggregate.particle_count --sweep")
        parser.add_argument("sweep_dir", type=Path, help="a sweep folder over model.Q (job folders inside)")
        return sweep_main(parser.parse_args(args[1:]).sweep_dir)
    job = read_job_metrics(
        "particle_count",
        "RMSE against particle count and time per step for a job's particle filters, and seed 001's efficiency "
        "ratios (with --sweep SWEEP_DIR: the trend over a sweep of model.Q).",
        args,
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
    efficiency = efficiency_table(metrics)
    if len(efficiency):
        efficiency.to_csv(job_dir / EFFICIENCY, index=False)
    written = [job_dir / "figures" / FIGURE, job_dir / SERIES] + ([job_dir / EFFICIENCY] if len(efficiency) else [])
    print("Wrote " + ", ".join(map(str, written)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
