"""The one job pipeline (docs/pipeline.md): every job kind (open loop, closed loop,
flight-log replay) runs its estimators through the same cache path, worker policy and failure
isolation, and its tables and summary.json have one writer each.

- a closed-loop job is served from the result cache like any other job, and writes what the
  computed job wrote (with the estimate fed back, each estimator's flight comes with its result);
- its estimators run in worker processes, with the same numbers as in one process;
- an estimator whose process dies, or whose result cannot come back, fails alone.
"""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import quadest.app.estimator_runs as estimator_runs
import quadest.app.pipeline as pipeline
from helpers import compose_config
from quadest.app.closed_loop_job import ClosedLoopJob
from quadest.app.estimator_runs import RunSettings, resolve_workers, run_estimators, worker_count
from quadest.app.job import job_kind, run_job
from quadest.app.open_loop_job import OpenLoopJob
from quadest.app.replay_job import ReplayJob
from quadest.app.settings import job_settings
from quadest.cache.lookup import JobCache
from quadest.closed_loop.quadrotor import QuadrotorLoop
from quadest.evaluation.formatting import strict_json

SRC = Path(__file__).resolve().parents[1] / "src" / "quadest"
TIMING = ["step_time_us", "from_cache"]
CLOSED = ["runs=2", "duration=0.5", "scenario=attitude_steps", "scenario.steps=[[0.2,0.0,4.0]]", "progress=false",
          "output.saved_runs=1", "output.figures=false"]  # fmt: skip
KINDS = {
    "open": (["runs=2", "duration=0.3", "estimator=[ekf]"], OpenLoopJob),
    "closed_truth": (["loop=truth", "estimator=[ekf]", *CLOSED], ClosedLoopJob),
    "closed_estimate": (["loop=estimate", "estimator=[ekf]", *CLOSED], ClosedLoopJob),
    "replay": (["experiment=px4_replay", "duration=6.0", "estimator=[mekf]"], ReplayJob),
}


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.slow
def test_every_job_kind_runs_through_the_one_pipeline(kind, tmp_path, monkeypatch):
    """One call each of the estimator runs (cache, workers, isolation), the table writer and the
    summary writer, whatever the kind; what they wrote is what the job returned."""
    overrides, expected = KINDS[kind]
    calls: dict[str, list] = {"runs": [], "tables": [], "summary": []}
    for name, key in (("run_estimators", "runs"), ("write_tables", "tables"), ("write_summary", "summary")):
        original = getattr(pipeline, name)

        def spy(*args, _original=original, _key=key, **kwargs):
            calls[_key].append(args)
            return _original(*args, **kwargs)

        monkeypatch.setattr(pipeline, name, spy)
    cfg = compose_config([*overrides, "workers=1", "progress=false", "output.figures=false"])
    assert isinstance(job_kind(job_settings(cfg)), expected)
    summary = run_job(cfg, tmp_path)
    assert {key: len(value) for key, value in calls.items()} == {"runs": 1, "tables": 1, "summary": 1}
    written = json.loads((tmp_path / "summary.json").read_text())
    assert written == json.loads(strict_json({k: v for k, v in summary.items() if not k.startswith("_")}))
    assert list(written)[:2] == ["schema_version", "status"] and list(written)[-2:] == ["cache", "estimators"]
    assert pd.read_csv(tmp_path / "metrics.csv")["from_cache"].eq(False).all()


def test_only_the_pipeline_writes_summary_json_and_the_metric_tables():
    """Source scan: ``summary.json`` is written by the pipeline (and, for a job that could not run at
    all, by the CLI's failure record), the four metric tables by ``job_tables.write_tables`` only."""
    writers: dict[str, set[str]] = {}
    files = ("summary.json", "metrics.csv", "rmse_summary.csv", "paired_comparison.csv", "rmse_table.md")
    for path in SRC.rglob("*.py"):
        for line in path.read_text().splitlines():
            for name in files:
                if f'"{name}"' in line and re.search(r"\.(write_text|to_csv|write_bytes|open)\(", line):
                    writers.setdefault(name, set()).add(path.relative_to(SRC).as_posix())
    assert writers.pop("summary.json") == {"app/pipeline.py", "app/cli.py"}
    assert writers == {name: {"evaluation/job_tables.py"} for name in files[1:]}


def _outputs(folder: Path) -> dict:
    """Every output of a closed-loop job that a cached job must reproduce, timing and cache aside."""
    out = {name: pd.read_csv(folder / name) for name in ("metrics.csv", "rmse_summary.csv", "paired_comparison.csv",
                                                          "control_metrics.csv", "control_summary.csv")}  # fmt: skip
    out["metrics.csv"] = out["metrics.csv"].drop(columns=TIMING)
    summary = json.loads((folder / "summary.json").read_text())
    for key in ("cache", "commit", "commit_dirty", "code_version"):
        summary.pop(key)
    for est in summary["estimators"].values():
        for key in TIMING:
            est.pop(key)
    out["summary.json"] = summary
    with np.load(folder / "timeseries.npz") as npz:
        out["timeseries.npz"] = {key: npz[key] for key in npz.files}
    return out


def _assert_same(got: dict, expected: dict) -> None:
    for name, value in expected.items():
        if isinstance(value, pd.DataFrame):
            pd.testing.assert_frame_equal(got[name], value, check_exact=True, obj=name)
        elif name == "timeseries.npz":
            assert list(got[name]) == list(value)
            for key, array in value.items():
                np.testing.assert_array_equal(got[name][key], array, err_msg=key)
        else:
            assert got[name] == value, name


@pytest.mark.parametrize("loop", ["truth", "estimate"])
def test_a_closed_loop_job_is_served_from_the_cache(loop, tmp_path, monkeypatch):
    """The second identical job flies nothing and runs no estimator: the shared flight comes with
    the data (``truth``), each estimator's own flight with its result (``estimate``); every output
    is the computed job's, the step times included."""
    flown: list[str] = []
    fly_shared, fly_estimator = QuadrotorLoop.fly_shared, QuadrotorLoop.fly_estimator
    run = estimator_runs.run_estimator

    def count_shared(self, mode):
        flown.append(mode)
        return fly_shared(self, mode)

    def count_own(self, name, *args):
        flown.append(name)
        return fly_estimator(self, name, *args)

    def count_run(name, *args, **kwargs):
        flown.append(f"{name} on the shared flight")
        return run(name, *args, **kwargs)

    monkeypatch.setattr(QuadrotorLoop, "fly_shared", count_shared)
    monkeypatch.setattr(QuadrotorLoop, "fly_estimator", count_own)
    monkeypatch.setattr(estimator_runs, "run_estimator", count_run)
    cfg = compose_config([f"loop={loop}", "estimator=[ekf,ukf]", "workers=1", f"cache.dir={tmp_path / 'cache'}",
                          *CLOSED])  # fmt: skip
    cold = run_job(cfg, tmp_path / "cold")
    assert flown == (["truth", "ekf on the shared flight", "ukf on the shared flight"] if loop == "truth"
                     else ["ekf", "ukf"])  # fmt: skip
    flown.clear()
    warm = run_job(cfg, tmp_path / "warm")
    assert flown == []
    assert warm["cache"] == {"enabled": True, "data_from_cache": loop == "truth"}
    for name, est in warm["estimators"].items():
        assert est["from_cache"] and est["step_time_us"] == cold["estimators"][name]["step_time_us"]
    assert pd.read_csv(tmp_path / "warm" / "metrics.csv")["from_cache"].all()
    _assert_same(_outputs(tmp_path / "warm"), _outputs(tmp_path / "cold"))


@pytest.mark.slow
def test_closed_loop_estimators_fly_in_worker_processes_with_the_same_numbers(tmp_path):
    """``workers`` is result-neutral in the closed loop too: with the estimate fed back, two
    estimators flown in two processes give what one process gives (the loop must pickle)."""
    base = ["loop=estimate", "estimator=[ekf,ukf]", "cache.enabled=false", *CLOSED]
    run_job(compose_config([*base, "workers=1"]), tmp_path / "one")
    run_job(compose_config([*base, "workers=2"]), tmp_path / "two")
    one, two = _outputs(tmp_path / "one"), _outputs(tmp_path / "two")
    assert not one["metrics.csv"]["diverged"].any()
    _assert_same(two, one)


def test_a_closed_loop_estimator_that_cannot_be_built_fails_alone(tmp_path):
    """With the estimate fed back, an estimator that raises at construction has no flight and every
    run flagged with the reason; the other estimator flies, is scored and is cached."""
    cfg = compose_config(["loop=estimate", "estimator=[ekf]", "+estimator.bad._target_=target_plugin.LinearizedKF",
                          "+estimator.bad.inflation=0.5", "workers=1", f"cache.dir={tmp_path / 'cache'}",
                          *CLOSED])  # fmt: skip
    summary = run_job(cfg, tmp_path / "a")
    bad = summary["estimators"]["bad"]
    assert bad["diverged"] == 2
    assert set(bad["failure_reasons"].values()) == {"ValueError: inflation must be >= 1, got 0.5"}
    assert summary["estimators"]["ekf"]["diverged"] == 0 and list(summary["crashes"]) == ["ekf"]
    assert set(pd.read_csv(tmp_path / "a" / "control_metrics.csv")["flown_by"]) == {"ekf"}
    with np.load(tmp_path / "a" / "timeseries.npz") as npz:
        assert np.isnan(npz["bad/truth"][:, 1:]).all() and np.isfinite(npz["ekf/truth"]).all()
    again = run_job(cfg, tmp_path / "b")
    assert again["estimators"]["ekf"]["from_cache"] and not again["estimators"]["bad"]["from_cache"]


def test_one_worker_policy():
    """Processes: as requested, or one per estimator up to the CPU count; never more than the
    estimators left to run, never fewer than one."""
    cpus = os.cpu_count() or 1
    assert resolve_workers(0, 3) == min(cpus, 3) and resolve_workers(0, 1) == 1 and resolve_workers(0, 0) == 1
    assert resolve_workers(4, 2) == 2 and resolve_workers(1, 5) == 1 and resolve_workers(2, 5) == 2
    assert resolve_workers(3, 0) == 1


@pytest.mark.parametrize("kind", KINDS)
def test_every_job_kind_can_send_its_estimators_to_worker_processes(kind):
    """The policy holds for every kind: its work pickles, so ``workers=2`` means two processes."""
    overrides, _ = KINDS[kind]
    job = job_kind(job_settings(compose_config([*overrides, "progress=false"])))
    work = job.work(job.make_data())
    assert worker_count(work, 2, 2) == 2 and worker_count(work, 1, 2) == 1 and worker_count(work, 0, 1) == 1


class Probe:
    """A job's work that needs no estimator: ``dies`` ends its process, ``unpicklable`` returns a
    result that cannot be sent back, ``raises`` raises, ``slow`` takes a second (still running
    when ``dies``, submitted before it, ends its process), the others return a text."""

    def run(self, label: str, node: dict, settings: RunSettings):
        if label == "dies":
            os._exit(3)
        if label == "slow":
            time.sleep(1.0)
        if label == "raises":
            raise RuntimeError("exploded")
        if label == "unpicklable":
            return lambda: None
        return f"{label} ran in {os.getpid()}"

    def failed(self, label: str, reason: str, settings: RunSettings):
        return f"{label} failed: {reason}"

    def shippable(self) -> bool:
        return True


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.slow
def test_an_estimator_that_raises_or_whose_process_dies_fails_alone(workers):
    """Whatever goes wrong with one estimator (it raises; with processes, its result cannot be
    pickled back, or its process dies) is recorded as its failure; every other estimator's result
    is there."""
    labels = ["first", "raises", "second", "unpicklable", "dies", "slow"] if workers > 1 else ["first", "raises"]
    results, from_cache = run_estimators(Probe(), {label: {} for label in labels}, JobCache(None, None),
                                         RunSettings(1e9, 0), workers)  # fmt: skip
    got = dict(zip(labels, results, strict=True))
    for label in ("first", "second", "slow"):
        if label in got:
            assert got[label].startswith(f"{label} ran in "), got[label]
    assert got["raises"] == "raises failed: RuntimeError: exploded"
    if workers > 1:
        assert got["unpicklable"].startswith("unpicklable failed: ") and "pickle" in got["unpicklable"].lower()
        assert got["dies"].startswith("dies failed: BrokenProcessPool")
    assert not any(from_cache.values())
