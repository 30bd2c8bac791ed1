"""The control tables of one closed-loop job (``docs/closed-loop.md``): ``control_metrics.csv``
(one row per flight, run and metric), ``control_summary.csv`` and ``control_table.md`` (mean and
95 % confidence interval over the runs), and their entry of ``summary.json``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from quadest.closed_loop.control_metrics import summarize_control
from quadest.closed_loop.loop import FlightRecord
from quadest.evaluation.formatting import markdown_table
from quadest.evaluation.job_tables import json_float


def control_table(flights: dict[str, FlightRecord | None], runs: int, loop: str) -> pd.DataFrame:
    """One row per (flight, run, metric): the value, and whether and why the run crashed; a flight
    that is ``None`` (an estimator that could not fly) has no rows."""
    frames = []
    for name, flight in flights.items():
        if flight is None:
            continue
        reasons = [flight.crash_reasons.get(i, "") for i in range(runs)]
        for metric, values in flight.metrics.items():
            frames.append(pd.DataFrame({"flown_by": name, "run": np.arange(runs), "metric": metric, "value": values,
                                        "crashed": flight.crashed, "crash_reason": reasons}))  # fmt: skip
    table = pd.concat(frames, ignore_index=True)
    table["loop"] = loop
    return table


def write_control_tables(out_dir: Path, control: pd.DataFrame) -> pd.DataFrame:
    """Write ``control_metrics.csv``, ``control_summary.csv`` and ``control_table.md``; returns the summary."""
    control.to_csv(out_dir / "control_metrics.csv", index=False)
    summary = summarize_control(control, ["loop", "flown_by"])
    summary.to_csv(out_dir / "control_summary.csv", index=False)
    (out_dir / "control_table.md").write_text(markdown_table(summary.round(4)))
    return summary


def control_entries(summary: pd.DataFrame) -> dict[str, dict]:
    """``summary.json["control"]``: mean, confidence interval and count per flight and metric."""
    return {
        f"{r['flown_by']}/{r['metric']}": {"mean": json_float(r["mean"]), "ci": [json_float(r["ci_lo"]),
                                           json_float(r["ci_hi"])], "n": int(r["n"])}
        for r in summary.to_dict("records")
    }  # fmt: skip
