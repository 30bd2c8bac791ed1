"""Read a sweep folder: one row per job × estimator × state of every job that succeeded, the
status of every expected job, and the swept parameters."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from quadest.evaluation.paired import paired_comparison

BASE_COLUMNS = {"job", "status", "error", "commit", "ci95_low", "ci95_high"}
"""Columns the aggregate adds itself. With them, every column of a job's ``rmse_summary.csv`` and
every metric of its ``summary.json`` entries (:func:`quadest.evaluation.job_tables.entry_metrics`)
is the aggregate's own: an override with such a name (``runs=20``) becomes ``override.<name>``."""
LEGACY_METRICS = ("step_time_us", "mean_nees", "nees_in_band", "mean_nis", "nis_in_band")
"""The entry metrics of a job written before ``summary.json`` listed them (``metric_keys``)."""


def own_columns(job_dir: Path) -> set[str]:
    """The aggregate's own column names for a job folder (its tables' and metrics' names)."""
    own = set(BASE_COLUMNS) | set(LEGACY_METRICS)
    table, summary_file = job_dir / "rmse_summary.csv", job_dir / "summary.json"
    if table.is_file():
        own |= set(pd.read_csv(table, nrows=0).columns)
    if summary_file.is_file():
        own |= set(json.loads(summary_file.read_text()).get("metric_keys", ()))
    return own


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


def _sweep_size(value) -> int:
    """Values of one override: a comma list is a sweep, a bracketed list or anything else is one."""
    text = str(value)
    return len(text.split(",")) if "," in text and not text.startswith("[") else 1


def expected_jobs(sweep_dir: Path) -> int | None:
    """Number of jobs the sweep's grid holds: the product of the sweep sizes of the sweeper params
    and the command-line overrides, where a command-line override of a key the params also list
    replaces it (as Hydra's basic sweeper does: the command line comes last and wins)."""
    path = sweep_dir / "multirun.yaml"
    if not path.is_file():
        return None
    record = yaml.safe_load(path.read_text()) or {}
    params = ((record.get("hydra") or {}).get("sweeper") or {}).get("params") or {}
    overrides = ((record.get("hydra") or {}).get("overrides") or {}).get("task") or []
    sizes = {str(key): _sweep_size(value) for key, value in params.items()}
    for item in overrides:
        key, _, value = str(item).partition("=")
        sizes[key] = _sweep_size(value)
    return int(np.prod(list(sizes.values()))) if sizes else 1


def swept_parameters(record: dict) -> dict:
    """The swept keys of a sweep's ``multirun.yaml`` record and their values: the sweeper's params,
    then the command-line overrides, which come last and win (as in :func:`expected_jobs`); a key
    the command line fixes to one value is not swept (``quadest -m alpha=0.1,0.5``: ``{alpha: 0.1,0.5}``)."""
    hydra = record.get("hydra") or {}
    values = dict((hydra.get("sweeper") or {}).get("params") or {})
    for item in (hydra.get("overrides") or {}).get("task") or []:
        key, _, value = str(item).partition("=")
        if _sweep_size(value) > 1:
            values[key] = value
        else:
            values.pop(key, None)
    return values


def load_sweep(sweep_dir: Path) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """(cells, jobs, parameter columns) of a sweep folder."""
    rows, jobs, params = [], [], []
    found = sorted((p for p in sweep_dir.iterdir() if p.is_dir() and p.name.isdigit()), key=lambda p: int(p.name))
    for job_dir in found:
        overrides_file = job_dir / ".hydra" / "overrides.yaml"
        overrides = yaml.safe_load(overrides_file.read_text()) if overrides_file.is_file() else []
        cell = {}
        own = own_columns(job_dir)
        for item in overrides or []:
            key, _, value = str(item).partition("=")
            key = key.lstrip("+~")
            key = f"override.{key}" if key in own else key
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
            for key in summary.get("metric_keys", LEGACY_METRICS):
                part[key] = est.get(key)
            for key, value in cell.items():
                part[key] = value if not isinstance(value, list) else str(value)
            rows.append(part)
    expected = expected_jobs(sweep_dir)
    present = {j["job"] for j in jobs}
    total = max(expected or 0, max(present, default=-1) + 1)
    for missing in sorted(set(range(total)) - present):
        jobs.append({"job": missing, "status": "missing", "error": ""})
    cells = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()
    return cells, pd.DataFrame(jobs).sort_values("job").reset_index(drop=True), params


def load_paired(sweep_dir: Path, jobs: pd.DataFrame, params: list[str]) -> pd.DataFrame:
    """Every finished cell's paired comparison (``<job>/paired_comparison.csv``; for a cell
    written before that file existed, computed from its ``metrics.csv`` with the job's seed), with
    the job number and the swept parameters as columns. Holm's family stays one cell."""
    frames = []
    for row in jobs[jobs["status"] == "ok"].to_dict("records"):
        job_dir = Path(sweep_dir) / str(row["job"])
        path = job_dir / "paired_comparison.csv"
        if path.is_file():
            table = pd.read_csv(path)
        else:
            table = paired_comparison(pd.read_csv(job_dir / "metrics.csv"))
        if table.empty:
            continue
        table.insert(0, "job", int(row["job"]))
        for i, key in enumerate(params):
            value = row.get(key)
            table.insert(1 + i, key, value if not isinstance(value, list) else str(value))
        frames.append(table)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
