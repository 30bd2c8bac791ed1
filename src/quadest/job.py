"""One job: build the Monte Carlo data, run every selected estimator, write the outputs.

The output folder's layout is documented in ``docs/outputs.md`` (schema version
:data:`SCHEMA_VERSION`).
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import subprocess
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf
from tqdm.auto import tqdm

from quadest.config.validate import validate
from quadest.estimators.registry import build_estimator, estimator_parameters
from quadest.formatting import markdown_table, strict_json
from quadest.metrics import estimator_overview, floor_table, rmse_table, summarize, tidy_metrics
from quadest.models.registry import build_data
from quadest.montecarlo import MonteCarloData
from quadest.paired import paired_comparison, paired_markdown, summary_lines
from quadest.pcrlb import pcrlb_variances
from quadest.plotting import plot_consistency, plot_errors, plot_rmse_vs_time, plot_truth_vs_estimate
from quadest.runner import EstimatorResult, run_estimator

SCHEMA_VERSION = 1


def git_commit() -> str:
    """The commit of the source tree, or ``"unknown"`` outside a git checkout."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True, timeout=5
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 else "unknown"


def failed_result(name: str, data: MonteCarloData, reason: str) -> EstimatorResult:
    """The result of an estimator that could not run at all: every run flagged with ``reason``."""
    B, K1, n = data.truth.shape
    nc = data.companion_truth.shape[-1]
    nan = np.full(B, np.nan)
    return EstimatorResult(
        name=name, sq_error_sum=np.full((B, n), np.nan), companion_sq_error_sum=np.full((B, nc), np.nan),
        steps=np.zeros(B), nees_sum=nan, nis_sum=nan.copy(), nees_mean_t=np.full(K1, np.nan),
        nis_mean_t=np.full(K1, np.nan), sq_error_t=np.zeros((K1, n)), alive_t=np.zeros(K1),
        diverged=np.ones(B, dtype=bool), diverged_step=np.zeros(B, dtype=int), reasons=dict.fromkeys(range(B), reason),
        step_time_us=float("nan"),
        saved={"estimate": np.full((0, K1, n), np.nan), "std": np.full((0, K1, n), np.nan),
               "companion": np.full((0, K1, nc), np.nan)},
    )  # fmt: skip


def resolve_workers(requested: int, estimators: int) -> int:
    """Processes to run the estimators in: ``requested``, or with 0 one per estimator up to the
    number of CPUs."""
    if requested > 0:
        return min(requested, estimators)
    return max(1, min(os.cpu_count() or 1, estimators))


def _picklable(data: MonteCarloData) -> bool:
    """Whether the data can go to worker processes: its arrays always can, a model built from
    closures cannot, so only the model is checked."""
    try:
        pickle.dumps(data.model)
    except (pickle.PicklingError, AttributeError, TypeError):
        return False
    return True


def _run_one(
    label: str, node: dict, data: MonteCarloData, bound: float, saved_runs: int, progress: bool
) -> EstimatorResult:
    """Build and run one estimator; any exception becomes a failed result with its text."""
    try:
        est = build_estimator(label, node, data.model)
        return run_estimator(label, est, data, bound, saved_runs, progress)
    except Exception as exc:  # a broken estimator is recorded, never fatal to the job
        return failed_result(label, data, f"{type(exc).__name__}: {exc}")


def run_job(cfg, out_dir: Path, overrides: list[str] | None = None) -> dict:
    """Validate ``cfg``, run the comparison and write every output into ``out_dir``.

    Returns the JSON summary. An estimator that raises (at construction or inside a run) is
    recorded as failed with the exception text; it does not stop the other estimators. With
    ``workers`` ≠ 1 the estimators run in separate processes on the same data (results do not
    depend on it: each estimator is deterministic given the data).
    """
    validate(cfg)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    data = build_data(cfg)
    saved_runs = min(int(cfg.output.saved_runs), int(cfg.runs))
    nodes = {label: OmegaConf.to_container(node, resolve=True) for label, node in cfg.estimator.items()}
    params = {label: {"kind": node.get("kind", label), **estimator_parameters(node)} for label, node in nodes.items()}
    workers = resolve_workers(int(cfg.workers), len(nodes)) if _picklable(data) else 1
    tasks = [
        (label, node, data, float(cfg.divergence_bound), saved_runs, bool(cfg.progress) and workers == 1)
        for label, node in nodes.items()
    ]
    if workers == 1:
        results = [_run_one(*task) for task in tasks]
    else:
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(_run_one, *task) for task in tasks]
            bar = tqdm(total=len(futures), desc="estimators", disable=None if cfg.progress else True, leave=False)
            for _ in as_completed(futures):
                bar.update()
            bar.close()
            results = [f.result() for f in futures]

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        table = tidy_metrics(results, data, params, {"seed": int(cfg.seed), "runs": int(cfg.runs)})
        bound = pcrlb_variances(data)
        summary_table = summarize(table).merge(
            floor_table(results, data, bound), on=["estimator", "quantity", "state"], how="left"
        )
        overview = estimator_overview(results, data.model.n_err, data.model.m)
    table.to_csv(out_dir / "metrics.csv", index=False)
    summary_table.to_csv(out_dir / "rmse_summary.csv", index=False)
    printed = rmse_table(summary_table)
    paired = paired_comparison(table, int(cfg.seed))
    paired.to_csv(out_dir / "paired_comparison.csv", index=False)
    (out_dir / "rmse_table.md").write_text(
        markdown_table(printed) + "\n" + markdown_table(overview.round(4)) + paired_markdown(paired)
    )
    if saved_runs:
        arrays = {
            "time": data.time,
            "truth": data.truth[:saved_runs],
            "companion_truth": data.companion_truth[:saved_runs],
        }
        for res in results:
            for key, value in res.saved.items():
                arrays[f"{res.name}/{key}"] = value
        np.savez_compressed(out_dir / "timeseries.npz", **arrays)
        if cfg.output.figures:
            fig_dir = out_dir / "figures"
            fig_dir.mkdir(exist_ok=True)
            ran = [r for r in results if r.saved["estimate"].shape[0]]
            plot_truth_vs_estimate(data, ran, fig_dir / "truth_vs_estimate.png")
            if cfg.output.per_estimator_figures:
                for res in ran:
                    plot_truth_vs_estimate(data, [res], fig_dir / f"truth_vs_estimate_{res.name}.png")
            plot_errors(data, ran, fig_dir / "errors_3sigma.png", bound)
            plot_rmse_vs_time(data, results, bound, fig_dir / "rmse_vs_time.png")
            plot_consistency(data, results, fig_dir / "consistency.png")

    summary = {
        "schema_version": SCHEMA_VERSION,
        "status": "ok",
        "commit": git_commit(),
        "overrides": list(overrides or []),
        "labels": {**data.labels, "seed": int(cfg.seed), "runs": int(cfg.runs),
                   "duration": float(cfg.duration), "sample_period": float(cfg.sample_period)},
        "state_names": list(data.model.state_names),
        "companion_names": list(data.model.companion_names),
        "measurement_names": list(data.model.measurement_names),
        "estimators": {},
    }  # fmt: skip
    for res, row in zip(results, overview.to_dict("records"), strict=True):
        rows = summary_table[summary_table["estimator"] == res.name]
        summary["estimators"][res.name] = {
            "parameters": params[res.name],
            "diverged": row["diverged"],
            "failure_reasons": {str(k): v for k, v in res.reasons.items()},
            "mean_nees": _json_float(row["mean_nees"]),
            "nees_in_band": _json_float(row["nees_in_band"]),
            "mean_nis": _json_float(row["mean_nis"]),
            "nis_in_band": _json_float(row["nis_in_band"]),
            "step_time_us": _json_float(row["step_time_us"]),
            "nis_by_sensor": {
                sensor: _json_float(np.nanmean(res.mean_sensor_nis(sensor))) if (~res.diverged).any() else None
                for sensor in res.sensor_nis
            },
            "rmse": {
                r["state"]: {"mean": _json_float(r["rmse_mean"]), "std": _json_float(r["rmse_std"]),
                             "pooled": _json_float(r["pooled_rmse"]), "pcrlb": _json_float(r["pcrlb"]),
                             "quantity": r["quantity"], "unit": r["unit"]}
                for r in rows.to_dict("records")
            },
        }  # fmt: skip
    (out_dir / "summary.json").write_text(strict_json(summary, indent=2))
    summary["_table"] = printed
    summary["_paired"] = summary_lines(paired)
    return summary


def _json_float(value) -> float | None:
    value = float(value)
    return None if np.isnan(value) else value
