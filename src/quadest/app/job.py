"""One job: build the Monte Carlo data, run every selected estimator, write the outputs.

The output folder's layout is documented in ``docs/outputs.md`` (schema version
:data:`SCHEMA_VERSION`).
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import subprocess
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf
from tqdm.auto import tqdm

from quadest.app.replay_report import write_replay_outputs
from quadest.app.validate import validate
from quadest.cache.keys import code_version
from quadest.cache.lookup import JobCache
from quadest.closed_loop.job import run_closed_loop_job
from quadest.errors import ConfigError
from quadest.estimators.registry import build_estimator, estimator_parameters, resolve
from quadest.evaluation.formatting import strict_json
from quadest.evaluation.job_tables import estimator_entries, write_metric_tables
from quadest.evaluation.metrics import convergence_table
from quadest.evaluation.paired import summary_lines
from quadest.evaluation.pcrlb import pcrlb_variances
from quadest.evaluation.plotting import (
    plot_consistency,
    plot_errors,
    plot_extra_figures,
    plot_rmse_vs_time,
    plot_truth_vs_estimate,
)
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult, failed_result
from quadest.runner import run_estimator
from quadest.simulation.registry import build_data

SCHEMA_VERSION = 1


def _git(*args: str) -> str | None:
    """``git ARGS`` in the package's folder: its output, or ``None`` outside a git checkout."""
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).parent, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def git_commit() -> str:
    """The commit of the source tree, or ``"unknown"`` outside a git checkout."""
    return _git("rev-parse", "HEAD") or "unknown"


def provenance() -> dict:
    """What made a job's numbers, for its ``summary.json``: ``commit`` (HEAD of the checkout),
    ``commit_dirty`` (whether the tracked code differed from that commit: the package source, the
    configs and the sweep files, ``src/``, ``conf/``, ``experiments/``; results being rewritten do
    not count; ``None`` outside git) and ``code_version`` (the digest of the package source and
    the numeric libraries' versions, :func:`quadest.cache.keys.code_version`, which names the code
    in a dirty tree and outside git too)."""
    status = _git("status", "--porcelain", "--untracked-files=no", "--", ":/src", ":/conf", ":/experiments")
    return {"commit": git_commit(), "commit_dirty": None if status is None else bool(status),
            "code_version": code_version()}  # fmt: skip


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
) -> tuple[EstimatorResult, bool]:
    """Build and run one estimator; any exception becomes a failed result with its text. The flag
    says whether the estimator ran to the end (only then is its result worth caching)."""
    try:
        est = build_estimator(label, node, data.model)
        return run_estimator(label, est, data, bound, saved_runs, progress), True
    except Exception as exc:  # a broken estimator is recorded, never fatal to the job
        return failed_result(label, data, f"{type(exc).__name__}: {exc}"), False


def _result_key(cache: JobCache, label: str, node: dict, bound: float, saved_runs: int) -> str | None:
    try:
        cls = resolve(label, node)[0]
    except ConfigError:  # validated already; if it still fails, _run_one records why
        return None
    return cache.result_key(label, node, cls, bound, saved_runs)


def run_estimators(
    cfg, data: MonteCarloData, nodes: dict[str, dict], saved_runs: int, cache: JobCache
) -> tuple[list[EstimatorResult], dict[str, bool]]:
    """Every estimator's result, in the order of ``nodes``, and whether each came from the cache.

    Only the estimators missing from the cache run (in ``workers`` processes when there are
    several); each result is stored as soon as it is done. A cached result is the object stored by
    the run that computed it, its ``step_time_us`` included.
    """
    bound = float(cfg.divergence_bound)
    keys = {label: _result_key(cache, label, node, bound, saved_runs) for label, node in nodes.items()}
    results = {label: cache.result(keys[label]) for label in nodes}
    from_cache = {label: result is not None for label, result in results.items()}
    todo = [label for label in nodes if results[label] is None]
    workers = resolve_workers(int(cfg.workers), len(todo)) if todo and _picklable(data) else 1
    tasks = {
        label: (label, nodes[label], data, bound, saved_runs, bool(cfg.progress) and workers == 1) for label in todo
    }

    def done(label: str, outcome: tuple[EstimatorResult, bool]) -> None:
        results[label], ran = outcome
        if ran:
            cache.keep(keys[label], results[label])

    if workers == 1:
        for label, task in tasks.items():
            done(label, _run_one(*task))
    else:
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {pool.submit(_run_one, *task): label for label, task in tasks.items()}
            bar = tqdm(total=len(futures), desc="estimators", disable=None if cfg.progress else True, leave=False)
            for future in as_completed(futures):
                done(futures[future], future.result())
                bar.update()
            bar.close()
    return [results[label] for label in nodes], from_cache


def run_job(cfg, out_dir: Path, overrides: list[str] | None = None) -> dict:
    """Validate ``cfg``, run the comparison and write every output into ``out_dir``.

    Returns the JSON summary. An estimator that raises (at construction or inside a run) is
    recorded as failed with the exception text; it does not stop the other estimators. With
    ``workers`` ≠ 1 the estimators run in separate processes on the same data (results do not
    depend on it: each estimator is deterministic given the data).
    """
    validate(cfg)
    if cfg.loop != "open":  # the controller flies on truth, noisy states or each estimate: docs/closed-loop.md
        header = {"schema_version": SCHEMA_VERSION, **provenance()}
        return run_closed_loop_job(cfg, out_dir, overrides, header)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    cache = JobCache.for_job(cfg)
    data, data_from_cache = cache.data(lambda: build_data(cfg))
    saved_runs = min(int(cfg.output.saved_runs), int(cfg.runs))
    nodes = {label: OmegaConf.to_container(node, resolve=True) for label, node in cfg.estimator.items()}
    params = {label: {"kind": node.get("kind", label), **estimator_parameters(node)} for label, node in nodes.items()}
    results, from_cache = run_estimators(cfg, data, nodes, saved_runs, cache)
    if "reference" in data.labels:  # a flight-log replay: differences to a reference, not errors (docs/replay.md)
        header = {"schema_version": SCHEMA_VERSION, "status": "ok", **provenance(),
                  "overrides": list(overrides or []), "cache": {"enabled": bool(cfg.cache.enabled),
                                                                "data_from_cache": data_from_cache}}  # fmt: skip
        return write_replay_outputs(cfg, out_dir, data, results, params, header, from_cache)

    bound = cache.derived("pcrlb", lambda: pcrlb_variances(data))
    labels = {"seed": int(cfg.seed), "runs": int(cfg.runs)}
    tables = write_metric_tables(out_dir, results, data, params, labels, bound, int(cfg.seed), from_cache)
    if data.model.bias_states:
        convergence_table(results, data).to_csv(out_dir / "convergence.csv", index=False)
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
            plot_extra_figures(data.model, arrays, fig_dir)

    summary = {
        "schema_version": SCHEMA_VERSION,
        "status": "ok",
        **provenance(),
        "overrides": list(overrides or []),
        "labels": {**data.labels, "seed": int(cfg.seed), "runs": int(cfg.runs),
                   "duration": float(cfg.duration), "sample_period": float(cfg.sample_period)},
        "state_names": list(data.model.state_names),
        "error_names": list(data.model.error_names),
        "companion_names": list(data.model.companion_names),
        "measurement_names": list(data.model.measurement_names),
        "cache": {"enabled": bool(cfg.cache.enabled), "data_from_cache": data_from_cache},
        "estimators": {},
    }  # fmt: skip
    summary["estimators"] = estimator_entries(results, tables, params, from_cache)
    (out_dir / "summary.json").write_text(strict_json(summary, indent=2))
    summary["_table"] = tables.printed
    summary["_paired"] = summary_lines(tables.paired)
    return summary
