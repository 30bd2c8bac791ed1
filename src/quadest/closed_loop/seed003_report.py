"""Seed 003's table: EKF in and EKF out side by side, with paired 95 % confidence intervals.

The sweep of ``experiment=seed003_closed_loop`` flies ``loop`` = ``truth``, ``measured`` (EKF out)
and ``estimate`` (EKF in) from the same seed, so run i of every arm flies on the same draws
(common random numbers). Per metric and step this module reports each arm's mean with its 95 %
Student-t CI over the runs, and the paired difference EKF in − EKF out (mean and 95 % Student-t CI
of the per-run differences, over the runs with a value in both arms), beside seed 003's printed
numbers (its §4 and Fig. 1). ``hydra.callbacks`` target: :class:`quadest.app.callbacks.Seed003Report`; outputs in
``<sweep>/seed003/``: ``seed003_table.csv`` (``ci_low``/``ci_high`` columns), ``seed003_table.md``,
``model_error.csv`` (the one-step model error of the filter along run 0 of each arm, what Q
stands for) and ``tracking.png``. Beside the control metrics the table holds the EKF's per-run
estimation RMSE per state (``estimate_rmse``, from each job's ``metrics.csv``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from quadest.closed_loop.control_metrics import mean_ci, step_events
from quadest.closed_loop.figures import plot_tracking
from quadest.closed_loop.report import format_cell
from quadest.evaluation.formatting import markdown_table
from quadest.models.schemas import Seed003AttitudeModelConf
from quadest.models.seed003_attitude import AttitudeRateModel, one_step_error_variance, seed003_filter_model

ARMS = {"estimate": "ekf_in", "measured": "ekf_out", "truth": "truth"}
# Seed 003's printed numbers (§4, Fig. 1), by (metric, step, arm).
SEED_VALUES = {
    ("overshoot_pct", "roll 0->4 deg at 5 s", "ekf_in"): "2.41",
    ("settling_time_s", "roll 0->4 deg at 5 s", "ekf_in"): "< 1",
    ("steady_state_error_pct", "roll 0->4 deg at 5 s", "ekf_in"): "<= 0.80",
    ("settling_time_s", "pitch 0->4 deg at 10 s", "ekf_in"): "< 1",
    ("steady_state_error_pct", "pitch 0->4 deg at 10 s", "ekf_in"): "<= 1.16",
    ("peak_error_pct", "roll 0->4 deg at 5 s", "ekf_out"): "45 (1.8 deg)",
}


def _split(metric: str) -> tuple[str, str]:
    """``"overshoot_pct[roll 0->4 deg at 5 s]"`` → (``"overshoot_pct"``, ``"roll 0->4 deg at 5 s"``)."""
    if metric.endswith("]") and "[" in metric:
        name, step = metric[:-1].split("[", 1)
        return name, step
    return metric, ""


def paired_rows(table: pd.DataFrame) -> pd.DataFrame:
    """One row per (metric, step, arm) with mean, ci_low, ci_high and n, plus the paired
    ``in_minus_out`` rows, from the per-run ``control_metrics.csv`` rows of every arm."""
    table = table.assign(arm=table["loop"].map(ARMS))
    wide = table.pivot_table(index=["metric", "run"], columns="arm", values="value", aggfunc="first", dropna=False)
    rows = []
    for metric in table["metric"].unique():
        per_run = wide.loc[metric]
        name, step = _split(metric)
        arms = [a for a in ("ekf_in", "ekf_out", "truth") if a in per_run.columns]
        if {"ekf_in", "ekf_out"} <= set(arms):
            arms.append("in_minus_out")
        for arm in arms:
            values = per_run["ekf_in"] - per_run["ekf_out"] if arm == "in_minus_out" else per_run[arm]
            m, lo, hi, n = mean_ci(values.to_numpy(dtype=float))
            rows.append({"metric": name, "step": step, "arm": arm, "mean": m, "ci_low": lo, "ci_high": hi, "n": n,
                         "runs": len(values), "seed_value": SEED_VALUES.get((name, step, arm), "")})  # fmt: skip
    return pd.DataFrame(rows)


def _estimation_rows(job: Path) -> pd.DataFrame:
    """The EKF's per-run RMSE per state of one job (``metrics.csv``) as ``estimate_rmse[<state>]``
    rows of the control table: how well the filter estimated in that arm (seed 003 Fig. 2)."""
    m = pd.read_csv(job / "metrics.csv")
    m = m[(m["estimator"] == "ekf") & (m["quantity"] == "filter")]
    value = m["rmse"].where(~m["diverged"].astype(bool))
    return pd.DataFrame({"loop": m["loop"], "run": m["run"], "metric": "estimate_rmse[" + m["state"] + "]",
                         "value": value})  # fmt: skip


def _cell(row: pd.Series) -> str:
    return format_cell(row["mean"], row["ci_low"], row["ci_high"], row["n"], row["runs"])


def markdown(rows: pd.DataFrame) -> str:
    """The table with one column per arm and the seed's value beside it."""
    rows = rows.assign(cell=rows.apply(_cell, axis=1))
    wide = rows.pivot_table(index=["metric", "step"], columns="arm", values="cell", aggfunc="first", sort=False)
    given = rows[rows["seed_value"] != ""]
    columns = (given[c] for c in ("metric", "step", "arm", "seed_value"))
    seed = {(m, s): f"{v} ({a})" for m, s, a, v in zip(*columns, strict=True)}
    wide["seed 003"] = [seed.get(key, "") for key in wide.index]
    columns = [c for c in ("truth", "ekf_out", "ekf_in", "in_minus_out", "seed 003") if c in wide.columns]
    return markdown_table(wide[columns].reset_index())


def seed003_report(sweep_dir: Path) -> Path:
    """Write ``sweep_dir/seed003/`` from the sweep's jobs (see the module docstring); returns the
    CSV's path."""
    sweep_dir = Path(sweep_dir)
    out = sweep_dir / "seed003"
    out.mkdir(parents=True, exist_ok=True)
    jobs = sorted(p.parent for p in sweep_dir.glob("*/control_metrics.csv"))
    table = pd.concat([pd.read_csv(job / "control_metrics.csv") for job in jobs], ignore_index=True)
    rows = paired_rows(pd.concat([table, *(_estimation_rows(job) for job in jobs)], ignore_index=True))
    rows.to_csv(out / "seed003_table.csv", index=False)
    record = yaml.safe_load((jobs[0] / "config.yaml").read_text())  # the config a job wrote, a plain dict
    window = record["closed_loop"]["transient_window"]
    crashes = table.drop_duplicates(["loop", "run"]).groupby("loop")["crashed"].sum()
    lines = [
        "# Seed 003 on the quadrotor: EKF in vs EKF out (mean [95 % CI] over the runs; in_minus_out: paired)",
        "",
        f"{int(record['runs'])} runs per arm, the same draws in every arm; truth: the controller reads the true state. "
        f"Overshoot: peak within {window} s of the step; peak error: max |error| after "
        "that window; steady-state error: mean over the last second before the next step; all in % of the step.",
        "",
        markdown(rows),
        "",
        "Crashed runs: " + ", ".join(f"{ARMS[loop]} {int(n)}" for loop, n in crashes.items()),
        "",
    ]
    (out / "seed003_table.md").write_text("\n".join(lines))
    _figures(jobs, record, out)
    return out / "seed003_table.csv"


def _figures(jobs: list[Path], record: dict, out: Path) -> None:
    """``tracking.png`` and ``model_error.csv`` from run 0 of every arm that saved it; ``record`` is
    the first job's ``config.yaml``."""
    model_settings = Seed003AttitudeModelConf(**record["model"])  # the filter model reads its top-level keys only
    model: AttitudeRateModel = seed003_filter_model(model_settings, float(record["sample_period"]), 1)
    responses, errors, time, reference = {}, [], None, None
    for job in jobs:
        series = job / "timeseries.npz"
        if not series.is_file():
            continue
        loop = pd.read_csv(job / "control_metrics.csv")["loop"].iloc[0]
        with np.load(series) as arrays:
            time, reference = arrays["time"], arrays["reference"]
            truth = next(arrays[k] for k in arrays.files if k.startswith("flight/") and k.endswith("/truth"))
        responses[{"truth": "truth fed", "measured": "EKF out", "estimate": "EKF in"}[loop]] = truth[0]
        errors.append({"arm": ARMS[loop], **dict(zip(model.state_names, one_step_error_variance(model, truth[:1]),
                                                     strict=True))})  # fmt: skip
    if responses:
        events = step_events(record["scenario"]["steps"], float(record["duration"]))
        plot_tracking(time, reference, responses, events, out / "tracking.png",
                      "Seed 003 on the quadrotor, run 0: EKF in vs EKF out (noisy states fed)")  # fmt: skip
        pd.DataFrame(errors).to_csv(out / "model_error.csv", index=False)
