"""The loop modes of a sweep side by side: one control table with 95 % confidence intervals and the
roll and pitch tracking figure (``hydra.callbacks`` in an experiment file: ``_target_:
quadest.app.callbacks.ClosedLoopReport``), written to ``<sweep>/closed_loop/``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from quadest.closed_loop.control_metrics import step_events, summarize_control
from quadest.closed_loop.figures import plot_tracking
from quadest.evaluation.formatting import markdown_table


def format_cell(mean: float, low: float, high: float, n: int, runs: int) -> str:
    """``mean [low, high]`` to three digits, ``(n=…)`` when fewer than ``runs`` runs have a value,
    ``-`` when none has."""
    if not np.isfinite(mean):
        return "-"
    ci = f" [{low:.3g}, {high:.3g}]" if np.isfinite(low) else ""
    count = f" (n={n})" if n < runs else ""
    return f"{mean:.3g}{ci}{count}"


def _format(row: pd.Series) -> str:
    return format_cell(row["mean"], row["ci_lo"], row["ci_hi"], row["n"], row["runs"])


def control_report(sweep_dir: Path) -> Path:
    """Collect every job's ``control_metrics.csv`` and ``timeseries.npz`` under ``sweep_dir`` into
    ``sweep_dir/closed_loop/``: ``control_summary.csv`` (mean, CI, n per loop, flight and metric),
    ``control_table.md`` (one column per flight) and ``tracking.png``; returns the table's path."""
    sweep_dir = Path(sweep_dir)
    out = sweep_dir / "closed_loop"
    out.mkdir(parents=True, exist_ok=True)
    jobs = sorted(p.parent for p in sweep_dir.glob("*/control_metrics.csv"))
    table = pd.concat([pd.read_csv(job / "control_metrics.csv") for job in jobs], ignore_index=True)
    summary = summarize_control(table, ["loop", "flown_by"])
    summary.to_csv(out / "control_summary.csv", index=False)
    summary["column"] = summary["loop"] + ": " + summary["flown_by"]
    summary["cell"] = summary.apply(_format, axis=1)
    wide = summary.pivot(index="metric", columns="column", values="cell").reindex(summary["metric"].unique())
    crashes = table.drop_duplicates(["loop", "flown_by", "run"]).groupby(["loop", "flown_by"])["crashed"].sum()
    lines = [
        "# Control metrics per loop mode (mean [95 % CI] over the runs; n: runs with a value)",
        "",
        markdown_table(wide.reset_index()),
        "",
        "Crashed runs: " + ", ".join(f"{loop}: {name} {int(n)}" for (loop, name), n in crashes.items()),
        "",
    ]
    (out / "control_table.md").write_text("\n".join(lines))

    record = yaml.safe_load((jobs[0] / "config.yaml").read_text())
    steps = record["scenario"].get("steps", [])
    events = step_events(steps, float(record["duration"]))
    responses, time, reference = {}, None, None
    for job in jobs:
        series = job / "timeseries.npz"
        if not series.is_file():
            continue
        with np.load(series) as arrays:
            time, reference = arrays["time"], arrays["reference"]
            loop = pd.read_csv(job / "control_metrics.csv")["loop"].iloc[0]
            for key in arrays.files:
                if key.startswith("flight/") and key.endswith("/truth"):
                    name = key.split("/")[1]
                    responses[loop if name == loop else f"{loop}: {name}"] = arrays[key][0]
    if responses:
        plot_tracking(time, reference, responses, events, out / "tracking.png",
                      "Roll and pitch tracking, run 0: estimator in the loop vs noisy-state feedback")  # fmt: skip
    return out / "control_table.md"
