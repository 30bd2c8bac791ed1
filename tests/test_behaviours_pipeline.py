"""Pipeline behaviours a single-point bug breaks without any other test noticing.

- a smoothed row (``<label>+smoothed``, ``<label>+lag<L>``) carries its filter's ``from_cache``
  flag, whichever it is;
- work whose model cannot be pickled never goes to a worker process, for every kind of work a job
  hands the estimator runs (open loop, closed loop watching one flight, closed loop flying each
  estimator); it runs in the job's own process instead, with the same results.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import quadest.app.estimator_runs as estimator_runs
from helpers import compose_config, compose_settings
from quadest.app.estimator_runs import RunSettings, run_estimators, worker_count
from quadest.app.job import job_kind
from quadest.app.pipeline import table_rows
from quadest.app.settings import job_settings
from quadest.cache.lookup import JobCache
from quadest.montecarlo.results import failed_result
from quadest.simulation.registry import build_data


@pytest.mark.parametrize("cached", [False, True])
def test_a_smoothed_row_is_marked_from_cache_exactly_as_its_filters_row(cached):
    """Two filters, one with a smoother, the other's flag the opposite: each smoothed row's flag
    is its own filter's."""
    data = build_data(compose_settings(["model=linear", "runs=2", "duration=0.3", "progress=false"]))
    smoothed = failed_result("a+smoothed", data, "probe")
    a = dataclasses.replace(failed_result("a", data, "probe"), smoothed=smoothed)
    b = dataclasses.replace(failed_result("b", data, "probe"), smoothed=failed_result("b+lag3", data, "probe"))
    rows = table_rows([a, b], {"a": {"kind": "ekf"}, "b": {"kind": "ukf"}}, {"a": cached, "b": not cached})
    assert [r.name for r in rows.results] == ["a", "a+smoothed", "b", "b+lag3"]
    assert rows.from_cache == {"a": cached, "a+smoothed": cached, "b": not cached, "b+lag3": not cached}


CLOSED = ["duration=0.3", "scenario=attitude_steps", "scenario.steps=[[0.1,0.0,4.0]]", "output.saved_runs=1",
          "output.figures=false"]  # fmt: skip
KINDS = {
    "open": ["duration=0.3"],
    "closed_truth": ["loop=truth", *CLOSED],
    "closed_estimate": ["loop=estimate", *CLOSED],
}


def unpicklable(work):
    """``work`` with a closure on the model it runs (the data's model, or the loop that builds it)."""
    owner = work.data.model if hasattr(work, "data") else work.loop
    owner.closure = lambda x: x
    return work


@pytest.mark.parametrize("kind", KINDS)
def test_work_whose_model_cannot_be_pickled_runs_in_the_jobs_own_process(kind, monkeypatch):
    """``workers=2`` with two estimators: no pool is made, and both estimators run (none is
    recorded as failed for a pickling error)."""
    cfg = compose_config([*KINDS[kind], "runs=2", "estimator=[ekf,ukf]", "workers=2", "progress=false"])
    job = job_kind(job_settings(cfg))
    work = unpicklable(job.work(job.make_data()))
    assert worker_count(work, 2, 2) == 1

    def no_pool(processes):
        raise AssertionError("unpicklable work was sent to worker processes")

    monkeypatch.setattr(estimator_runs, "_pool", no_pool)
    nodes = {label: dict(node) for label, node in cfg.estimator.items()}
    results, _ = run_estimators(work, nodes, JobCache(None, None), RunSettings(1e6, 1), 2)
    for result in results:
        assert not result.reasons, result.reasons
        assert np.all(np.isfinite(result.sq_error_sum))
