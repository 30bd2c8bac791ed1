"""``runs=auto``: an open-loop job that adds Monte Carlo runs until its comparisons decide.

The job runs in batches of ``decision.batch`` runs: batch ``b`` is runs ``b·batch ..
(b+1)·batch − 1``, made from those runs' own streams (``DataSettings.first_run``,
:func:`quadest.montecarlo.streams.run_streams`), so the batches together are the runs of one long
job. Each batch is one unit of the result cache: its data under the key of the job with
``runs = batch`` plus its first run (:func:`quadest.app.settings.batch_data_key`), each
estimator's result on it under that data key. So the first batch *is* the job with ``runs =
batch``, and a job with a larger budget, or started again, loads every batch it shares.

After each batch (a *look*) every open comparison (:func:`comparison_pairs` × the states of the
metrics table) gets the interval of :mod:`quadest.evaluation.sequential` at that look's spent α,
and a verdict if the interval decides it. The job stops at the first look where every comparison
has a verdict, or after ``decision.max_runs`` runs; then its report is the one of any open-loop job
on all its runs (:func:`quadest.app.pipeline.finish_job`, the batches' results concatenated by
:func:`quadest.montecarlo.batches.concatenate_results`), plus ``decisions.csv`` and the decisions
table below the printed RMSE table. The PCRLB, the saved series and the figures come from the first
batch's data (the first runs, as in any job).
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from omegaconf import DictConfig

from quadest.app.estimator_runs import run_estimators
from quadest.app.open_loop_job import OpenLoopJob
from quadest.app.pipeline import Ran, finish_job, run_settings, start_job
from quadest.app.schema import AUTO, DecisionConf, ExperimentConf, is_auto
from quadest.app.settings import JobSettings, batch_data_key
from quadest.cache.lookup import JobCache
from quadest.errors import ConfigError
from quadest.estimators.registry import estimator_parameters
from quadest.evaluation.formatting import markdown_table
from quadest.evaluation.metrics import tidy_metrics
from quadest.evaluation.paired import paired_differences, paired_runs, rmse_by_run
from quadest.evaluation.sequential import Decisions, Interval, look_alphas, relative_difference_interval
from quadest.montecarlo.batches import concatenate_results

DECISION_COLUMNS = ("pair", "state", "verdict", "runs", "estimate", "ci_low", "ci_high", "margin")


def validate_runs(experiment: ExperimentConf) -> None:
    """``runs``: an integer ≥ 1, or ``auto`` on a simulated open-loop job; and ``decision.*``
    (checked whatever ``runs`` is, so that a sweep's bad value fails before its first cell)."""
    runs = experiment.runs
    if is_auto(runs):
        if experiment.loop != "open" or experiment.source is not None:
            raise ConfigError("runs", runs, "an integer >= 1 here: auto is for simulated open-loop jobs (loop=open)")
        if experiment.output.saved_runs > experiment.decision.batch:
            raise ConfigError("output.saved_runs", experiment.output.saved_runs,
                              f"must be <= decision.batch={experiment.decision.batch} with runs=auto")  # fmt: skip
    elif isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ConfigError("runs", runs, "an integer >= 1, or auto (add runs until every comparison decides)")
    validate_decision(experiment.decision, list(experiment.estimator), is_auto(runs))


def validate_decision(rules: DecisionConf, labels: list[str], auto: bool) -> None:
    """One line naming the first bad ``decision.*`` value."""
    if rules.batch < 2:
        raise ConfigError("decision.batch", rules.batch, "an integer >= 2 (runs per look)")
    if rules.max_runs < rules.batch or rules.max_runs % rules.batch:
        raise ConfigError("decision.max_runs", rules.max_runs,
                          f"a multiple of decision.batch={rules.batch}, at least one batch")  # fmt: skip
    if not 0.0 < rules.alpha < 1.0:
        raise ConfigError("decision.alpha", rules.alpha, "in (0, 1)")
    if not rules.margin > 0.0:
        raise ConfigError("decision.margin", rules.margin, "> 0 (in % of the reference's RMSE)")
    for pair in rules.pairs or []:
        parts = split_pair(pair)
        if parts is None or parts[0] == parts[1] or not set(parts) <= set(labels):
            allowed = f"'estimator - reference', two different labels of {labels}"
            raise ConfigError("decision.pairs", pair, allowed)
    if auto and not rules.pairs and len(labels) < 2:
        raise ConfigError("runs", AUTO, "needs at least two estimators to compare (or decision.pairs)")


def split_pair(pair: str) -> tuple[str, str] | None:
    """``"ukf - ekf"`` → ``("ukf", "ekf")`` (the naming of ``paired_comparison.csv``); ``None`` if
    ``pair`` is not of that form."""
    parts = [p.strip() for p in str(pair).split(" - ")]
    return (parts[0], parts[1]) if len(parts) == 2 and all(parts) else None


def comparison_pairs(experiment: ExperimentConf) -> list[tuple[str, str]]:
    """(estimator, reference) of each comparison: ``decision.pairs``, else every estimator
    against the first."""
    if experiment.decision.pairs:
        return [split_pair(p) for p in experiment.decision.pairs]  # type: ignore[misc]
    first, *others = list(experiment.estimator)
    return [(label, first) for label in others]


def run_until_decided(job: JobSettings, cfg: DictConfig, out_dir: Path, overrides: list[str] | None = None) -> dict:
    """Run the ``runs=auto`` job ``job`` (module docstring); returns the summary of
    :func:`quadest.app.pipeline.finish_job` with ``decisions`` (the table of ``decisions.csv``)
    and the decisions printed below the RMSE table (``_after_table``)."""
    out_dir = start_job(cfg, out_dir)
    exp = job.experiment
    batches: list[Ran] = []
    decisions, runs = decide(exp, lambda first_run: _run_batch(job, cfg, first_run, batches))
    final = JobSettings(replace(exp, runs=runs), replace(job.data, runs=runs))
    labels = list(exp.estimator)
    ran = Ran(
        data=batches[0].data,
        data_from_cache=all(b.data_from_cache for b in batches),
        results=[concatenate_results([b.results[i] for b in batches]) for i in range(len(labels))],
        from_cache={label: all(b.from_cache[label] for b in batches) for label in labels},
        derived=batches[0].derived,
    )
    summary = finish_job(OpenLoopJob(final), final, out_dir, overrides, ran)
    decisions.to_csv(out_dir / "decisions.csv", index=False)
    summary["_after_table"] = decisions_text(decisions, exp.decision, runs)
    return summary


def _run_batch(job: JobSettings, cfg: DictConfig, first_run: int, batches: list[Ran]) -> pd.DataFrame:
    """Run the batch from run ``first_run`` on through the cache, keep it in ``batches`` and
    return the tidy metrics of every batch so far (runs numbered from 0)."""
    exp, batch = job.experiment, job.experiment.decision.batch
    batch_job = JobSettings(replace(exp, runs=batch), replace(job.data, runs=batch, first_run=first_run))
    kind = OpenLoopJob(batch_job)
    cache = JobCache.for_job(exp.cache, batch_data_key(cfg, batch, first_run) if exp.cache.enabled else None)
    data, data_from_cache = cache.data(kind.make_data)
    if data.estimator_seeds[0].spawn_key[:1] != (first_run,):
        raise ConfigError("runs", AUTO, f"model {job.data.model.name}'s data builder ignores DataSettings.first_run "
                          "(its batches would repeat the same runs; docs/models.md)")  # fmt: skip
    settings = run_settings(batch_job, batch)
    results, from_cache = run_estimators(kind.work(data), exp.estimator, cache, settings, int(exp.workers))
    kept = data if not batches else None  # only the first batch's data is reported: the others are let go
    batches.append(Ran(kept, data_from_cache, results, from_cache, cache.derived))
    merged = [concatenate_results([b.results[i] for b in batches]) for i in range(len(results))]
    params = {label: estimator_parameters(node) for label, node in exp.estimator.items()}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return tidy_metrics(merged, batches[0].data, params, {})


def decide(experiment: ExperimentConf, run_batch: Callable[[int], pd.DataFrame]) -> tuple[pd.DataFrame, int]:
    """The looks of a ``runs=auto`` job: ``run_batch(first_run)`` runs the next batch and returns
    the tidy metrics (``metrics.csv`` rows) of all runs so far; after each, every open comparison
    is looked at (:mod:`quadest.evaluation.sequential`), until all are decided or the budget is
    spent. Returns the table of ``decisions.csv`` and the runs made."""
    rules = experiment.decision
    pairs = comparison_pairs(experiment)
    looks = np.arange(rules.batch, rules.max_runs + 1, rules.batch)
    decisions = states = None
    for k, (runs, miss) in enumerate(zip(looks, look_alphas(looks, rules.max_runs, rules.alpha), strict=True)):
        _, states, wide = rmse_by_run(run_batch(int(runs - rules.batch)))
        intervals, used = [], []
        for estimator, reference in pairs:
            a, b, usable = paired_runs(wide, estimator, reference)
            intervals.append(relative_difference_interval(paired_differences(a, b), b, float(miss)))
            used.append(np.full(len(states), int(usable.sum())))
        if decisions is None:
            decisions = Decisions.open(len(pairs) * len(states))
        look = Interval(*(np.concatenate([getattr(i, f) for i in intervals]) for f in ("estimate", "low", "high")))
        decisions.look(look, np.concatenate(used), rules.margin, last=k == looks.size - 1)
        if experiment.progress:
            print(f"runs=auto: {runs} runs, {int((decisions.verdict != '').sum())} of {decisions.verdict.size} "
                  "comparisons decided", file=sys.stderr)  # fmt: skip
        if decisions.settled:
            break
    names = [f"{e} - {r}" for e, r in pairs for _ in range(len(states))]
    table = pd.DataFrame(
        {
            "pair": names, "state": list(states["state"]) * len(pairs), "verdict": decisions.verdict,
            "runs": decisions.runs, "estimate": decisions.estimate, "ci_low": decisions.low,
            "ci_high": decisions.high, "margin": rules.margin,
        }
    )  # fmt: skip
    return table[list(DECISION_COLUMNS)], int(runs)


def decisions_text(table: pd.DataFrame, rules: DecisionConf, runs: int) -> str:
    """The decisions below the printed RMSE table: one row per comparison."""
    counts = table["verdict"].value_counts()
    head = (
        f"Decisions (runs=auto, decisions.csv): {runs} of at most {rules.max_runs} runs, looks every {rules.batch}; "
        f"estimator - reference in % of the reference, interval at the deciding look's spent alpha "
        f"(each comparison at level {1 - rules.alpha:g} over all looks), equivalent within +-{rules.margin:g} %: "
        + ", ".join(f"{v} {n}" for v, n in counts.items())
    )
    cells = [
        "n/a (fewer than 2 usable runs)" if np.isnan(e) else f"{e:+.3g} [{lo:+.3g}, {hi:+.3g}]"
        for e, lo, hi in zip(table["estimate"], table["ci_low"], table["ci_high"], strict=True)
    ]
    rows = table.assign(**{"estimate [interval] %": cells})[
        ["pair", "state", "verdict", "runs", "estimate [interval] %"]
    ]
    return head + "\n\n" + markdown_table(rows) + "\n"
