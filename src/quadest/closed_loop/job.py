"""One job with the controller in the loop (``loop`` ≠ ``open``): fly, filter, score, write.

The outputs are those of an open-loop job (``docs/outputs.md``: ``metrics.csv``,
``rmse_summary.csv``, ``rmse_table.md``, ``paired_comparison.csv``, ``timeseries.npz``,
``summary.json``, figures), scored against each estimator's own truth, plus the control metrics
(``control_metrics.csv`` per run, ``control_summary.csv`` and ``control_table.md`` with 95 %
confidence intervals) and ``figures/tracking.png``. ``docs/closed-loop.md`` describes them.

With ``loop: estimate`` every estimator flies its own truth, so the PCRLB (a bound along one
truth) is left out: its column is empty and ``summary.json`` says why.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from omegaconf import OmegaConf

from quadest.closed_loop.control_metrics import summarize_control
from quadest.closed_loop.figures import plot_tracking
from quadest.closed_loop.loop import Flight
from quadest.closed_loop.quadrotor import QuadrotorLoop
from quadest.closed_loop.seed003 import closed_loop_for
from quadest.config.closed_loop import validate_loop
from quadest.estimators.registry import build_estimator, estimator_parameters
from quadest.evaluation.formatting import markdown_table, strict_json
from quadest.evaluation.job_tables import estimator_entries, json_float, write_metric_tables
from quadest.evaluation.paired import summary_lines
from quadest.evaluation.pcrlb import pcrlb_caption, pcrlb_variances
from quadest.evaluation.plotting import plot_truth_vs_estimate
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult, failed_result
from quadest.runner import run_estimator

PCRLB_NOTE = "left out with loop=estimate: each estimator flies its own truth, and the PCRLB is a bound along one truth"


def _on_shared_flight(
    label: str, node: dict, data: MonteCarloData, flight: Flight, bound: float, saved: int
) -> EstimatorResult:
    """``truth`` / ``measured``: the estimator watches the shared flight; crashed runs end there."""
    try:
        est = build_estimator(label, node, data.model)
        return run_estimator(label, est, data, bound, saved, crashes=(flight.crash_step, flight.crash_reasons))
    except Exception as exc:  # a broken estimator is recorded, never fatal to the job
        return failed_result(label, data, f"{type(exc).__name__}: {exc}")


def _in_loop(
    loop: QuadrotorLoop, label: str, node: dict, bound: float, saved: int
) -> tuple[EstimatorResult, Flight | None, MonteCarloData]:
    """``estimate``: the estimator flies its own plants. An estimator that cannot be built (or
    raises in flight) has no flight; every run is flagged with the reason."""
    model = loop.filter_model()
    try:
        est = build_estimator(label, node, model)
        return loop.fly_estimator(label, est, bound, saved)
    except Exception as exc:  # a broken estimator is recorded, never fatal to the job
        data = loop.empty_data(model)
        return failed_result(label, data, f"{type(exc).__name__}: {exc}"), None, data


def _parallel(fn, tasks: list[tuple], workers: int) -> list:
    if workers == 1 or len(tasks) < 2:
        return [fn(*task) for task in tasks]
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        return [f.result() for f in [pool.submit(fn, *task) for task in tasks]]


def _control_table(loop: QuadrotorLoop, flights: dict[str, Flight | None], runs: int) -> pd.DataFrame:
    """One row per (flight, run, metric): the value, and whether and why the run crashed."""
    frames = []
    for name, flight in flights.items():
        if flight is None:
            continue
        reasons = [flight.crash_reasons.get(i, "") for i in range(runs)]
        for metric, values in loop.metrics(flight).items():
            frames.append(pd.DataFrame({"flown_by": name, "run": np.arange(runs), "metric": metric, "value": values,
                                        "crashed": flight.crashed, "crash_reason": reasons}))  # fmt: skip
    return pd.concat(frames, ignore_index=True)


def run_closed_loop_job(cfg, out_dir: Path, overrides: list[str] | None, header: dict) -> dict:
    """Run a closed-loop job (``loop`` ≠ ``open``) and write its outputs into ``out_dir``.

    ``header`` holds the summary's ``schema_version`` and ``commit``; an estimator that could not
    run is recorded with :func:`~quadest.montecarlo.results.failed_result`. Returns the JSON
    summary, with the printed tables under ``_table`` and ``_paired`` as the open-loop job does.
    """
    validate_loop(cfg)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(OmegaConf.to_yaml(cfg, resolve=True))
    mode, runs, bound = str(cfg.loop), int(cfg.runs), float(cfg.divergence_bound)
    saved = min(int(cfg.output.saved_runs), runs)
    nodes = {label: OmegaConf.to_container(node, resolve=True) for label, node in cfg.estimator.items()}
    params = {label: {"kind": node.get("kind", label), **estimator_parameters(node)} for label, node in nodes.items()}
    workers = int(cfg.workers) or multiprocessing.cpu_count()
    loop = closed_loop_for(cfg)

    if mode == "estimate":
        outcomes = _parallel(_in_loop, [(loop, label, node, bound, saved) for label, node in nodes.items()],
                             workers)  # fmt: skip
        results = [o[0] for o in outcomes]
        flights = {label: o[1] for label, o in zip(nodes, outcomes, strict=True)}
        own_data = {label: o[2] for label, o in zip(nodes, outcomes, strict=True)}
        data = next(iter(own_data.values()))
        K1, n = data.time.size, data.model.n_err
        pcrlb, pcrlb_note = np.full((K1, n), np.nan), PCRLB_NOTE
    else:
        flight, data = loop.fly_shared(mode)
        tasks = [(label, node, data, flight, bound, saved) for label, node in nodes.items()]
        results = _parallel(_on_shared_flight, tasks, workers)
        flights, own_data = {mode: flight}, dict.fromkeys(nodes, data)
        pcrlb, pcrlb_note = pcrlb_variances(data), None

    control = _control_table(loop, flights, runs)
    control["loop"] = mode
    control.to_csv(out_dir / "control_metrics.csv", index=False)
    control_summary = summarize_control(control, ["loop", "flown_by"])
    control_summary.to_csv(out_dir / "control_summary.csv", index=False)
    (out_dir / "control_table.md").write_text(markdown_table(control_summary.round(4)))

    labels = {"seed": int(cfg.seed), "runs": runs, "loop": mode}
    tables = write_metric_tables(out_dir, results, data, params, labels, pcrlb, int(cfg.seed))

    if saved:
        arrays = {"time": data.time, "reference": loop.reference_array()}
        for name, flight in flights.items():
            if flight is not None:
                arrays[f"flight/{name}/truth"] = flight.truth.state[:saved]
                arrays[f"flight/{name}/command"] = flight.truth.command[:saved]
        for res in results:
            own = own_data[res.name]
            arrays[f"{res.name}/truth"] = own.truth[:saved]
            arrays[f"{res.name}/companion_truth"] = own.companion_truth[:saved]
            for key, value in res.saved.items():
                arrays[f"{res.name}/{key}"] = value
        np.savez_compressed(out_dir / "timeseries.npz", **arrays)
        if cfg.output.figures:
            fig_dir = out_dir / "figures"
            fig_dir.mkdir(exist_ok=True)
            responses = {name: f.truth.state[0] for name, f in flights.items() if f is not None}
            plot_tracking(data.time, loop.reference_array(), responses, loop.events, fig_dir / "tracking.png",
                          f"Tracking, run 0, loop={mode}")  # fmt: skip
            for res in results:
                if res.saved["estimate"].shape[0]:
                    own = own_data[res.name]
                    view = replace(data, truth=own.truth, companion_truth=own.companion_truth)
                    plot_truth_vs_estimate(view, [res], fig_dir / f"truth_vs_estimate_{res.name}.png")

    summary = {
        **header,
        "status": "ok",
        "overrides": list(overrides or []),
        "labels": {**data.labels, "seed": int(cfg.seed), "runs": runs, "duration": float(cfg.duration),
                   "sample_period": float(cfg.sample_period), "loop": mode},
        "state_names": list(data.model.state_names),
        "companion_names": list(data.model.companion_names),
        "measurement_names": list(data.model.measurement_names),
        "pcrlb_note": pcrlb_note,
        "control": {
            f"{r['flown_by']}/{r['metric']}": {"mean": json_float(r["mean"]), "ci": [json_float(r["ci_lo"]),
                                               json_float(r["ci_hi"])], "n": int(r["n"])}
            for r in control_summary.to_dict("records")
        },
        "crashes": {name: int(f.crashed.sum()) for name, f in flights.items() if f is not None},
        "estimators": {},
    }  # fmt: skip
    summary["estimators"] = estimator_entries(results, tables, params, {})
    (out_dir / "summary.json").write_text(strict_json(summary, indent=2))
    summary["_table"] = tables.printed
    summary["_paired"] = summary_lines(tables.paired)
    summary["_caption"] = (
        f"Per-state RMSE, mean ± std over {runs} Monte Carlo runs, loop={mode}: the controller flies on "
        + {"truth": "the true state", "measured": "noisy states (closed_loop.state_sensor)",
           "estimate": "each estimator's estimate; RMSE against each estimator's own truth"}[mode]
        + f".\n{'PCRLB: ' + pcrlb_note if pcrlb_note else pcrlb_caption(cfg.model.name)}"
        + f"\nControl metrics: {out_dir / 'control_table.md'}"
    )  # fmt: skip
    return summary
