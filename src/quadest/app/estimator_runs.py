"""Running a job's estimators: one cache path, one worker policy, one failure isolation, for every
job kind (open loop, closed loop, flight-log replay; :mod:`quadest.app.pipeline`).

A job kind hands :func:`run_estimators` its :class:`Work`: what to do with one estimator (run it on
the job's data, or fly it in the control loop) and what its result is when that fails. Then:

- **cache**: each estimator's result is looked up under its estimator key (``docs/cache.md``) and
  stored as soon as it is done; only the missing ones run;
- **workers**: :func:`resolve_workers` processes (``workers``; 0: one per estimator up to the CPU
  count), one if the work cannot be sent to another process (a model built from closures);
- **failure isolation**: an estimator that raises, whose result cannot come back from its
  process, or whose process dies, is recorded with :meth:`Work.failed` and the exception text;
  the other estimators' results are kept. After a process died, the estimators still missing run
  again, each alone in a new process, so that one estimator can only take down itself. An
  estimator that refuses its configuration (:class:`~quadest.errors.ConfigError`) fails the job
  instead: a failed job, not a divergence.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np
from tqdm.auto import tqdm

from quadest.app.parent_watch import pool_options
from quadest.cache.lookup import JobCache
from quadest.errors import ConfigError
from quadest.estimators.registry import build_estimator, resolve
from quadest.estimators.smoother_settings import smoother_settings
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult, failed_result
from quadest.runner import run_estimator


@dataclass(frozen=True)
class RunSettings:
    """The runner settings of a job: in every estimator's cache key (``divergence_bound``,
    ``saved_runs`` = min(``output.saved_runs``, ``runs``)), and whether to draw progress bars."""

    divergence_bound: float
    saved_runs: int
    progress: bool = False


class Work(Protocol):
    """What a job does with one estimator; sent to worker processes, so it must pickle."""

    def run(self, label: str, node: dict, settings: RunSettings) -> EstimatorResult:
        """Build estimator ``label`` from its resolved config ``node`` and run it."""
        ...

    def failed(self, label: str, reason: str, settings: RunSettings) -> EstimatorResult:
        """The result of estimator ``label`` when it could not run: every run flagged with ``reason``."""
        ...

    def shippable(self) -> bool:
        """Whether the work can be sent to another process."""
        ...


@dataclass
class OnData:
    """Every estimator runs on the same recorded data (open loop, replay, and a closed loop whose
    flight does not depend on the estimator); ``crashes`` (crash step per run, −1 for none; run →
    reason) ends the runs of a crashed flight there."""

    data: MonteCarloData
    crashes: tuple[np.ndarray, dict[int, str]] | None = None

    def run(self, label: str, node: dict, settings: RunSettings) -> EstimatorResult:
        data = self.data
        est = build_estimator(label, node, data.model)
        smoother = smoother_settings(label, node, resolve(label, node)[0])
        return run_estimator(label, est, data, settings.divergence_bound, settings.saved_runs, settings.progress,
                             crashes=self.crashes, smoother=smoother)  # fmt: skip

    def failed(self, label: str, reason: str, settings: RunSettings) -> EstimatorResult:
        return failed_result(label, self.data, reason)

    def shippable(self) -> bool:
        """The data's arrays always pickle; a model built from closures does not, so only the
        model is checked."""
        return picklable(self.data.model)


def picklable(value: object) -> bool:
    """Whether ``value`` can be pickled (sent to a worker process)."""
    try:
        pickle.dumps(value)
    except (pickle.PicklingError, AttributeError, TypeError):
        return False
    return True


def resolve_workers(requested: int, estimators: int) -> int:
    """Processes to run the estimators in: ``requested``, or with 0 one per estimator up to the
    number of CPUs; never more than there are estimators to run, never fewer than one."""
    wanted = requested if requested > 0 else os.cpu_count() or 1
    return max(1, min(wanted, estimators))


def worker_count(work: Work, requested: int, estimators: int) -> int:
    """The processes a job runs ``estimators`` estimators in: :func:`resolve_workers`, or one when
    ``work`` cannot be sent to another process. The one worker policy of every job kind."""
    processes = resolve_workers(requested, estimators)
    return processes if processes == 1 or work.shippable() else 1


Outcome = tuple[EstimatorResult, bool]
"""An estimator's result, and whether it ran to the end (only then is it worth caching)."""


def _run_one(work: Work, label: str, node: dict, settings: RunSettings) -> Outcome:
    """Run one estimator; any exception but a :class:`ConfigError` becomes a failed result with its
    text. A ``ConfigError`` (the estimator refuses its configuration) fails the job: it is no
    divergence, and no run of that configuration could succeed."""
    try:
        return work.run(label, node, settings), True
    except ConfigError:
        raise
    except Exception as exc:  # a broken estimator is recorded, never fatal to the job
        return work.failed(label, f"{type(exc).__name__}: {exc}", settings), False


def _result_key(cache: JobCache, label: str, node: dict, settings: RunSettings) -> str | None:
    try:
        cls = resolve(label, node)[0]
    except ConfigError:  # validated already; if it still fails, _run_one records why
        return None
    return cache.result_key(label, node, cls, settings.divergence_bound, settings.saved_runs)


def run_estimators(
    work: Work,
    nodes: dict[str, dict],
    cache: JobCache,
    settings: RunSettings,
    workers: int,
    announce: Callable[[str], None] | None = None,
) -> tuple[list[EstimatorResult], dict[str, bool]]:
    """Every estimator's result, in the order of ``nodes`` (label → resolved config), and whether
    each came from the cache (module docstring). A cached result is the object stored by the run
    that computed it, its ``step_time_us`` included. ``announce(label)`` is called as each
    estimator that ran is done (a long job's progress lines, :mod:`quadest.app.pipeline`)."""
    keys = {label: _result_key(cache, label, node, settings) for label, node in nodes.items()}
    results = {label: cache.result(keys[label]) for label in nodes}
    from_cache = {label: result is not None for label, result in results.items()}
    todo = {label: node for label, node in nodes.items() if results[label] is None}
    processes = worker_count(work, workers, len(todo))
    show_bar = settings.progress  # with processes: one bar over the estimators, none per estimator
    settings = replace(settings, progress=settings.progress and processes == 1)

    def done(label: str, outcome: Outcome) -> None:
        results[label], ran = outcome
        if ran:
            cache.keep(keys[label], results[label])
        if announce is not None:
            announce(label)

    if processes == 1:
        for label, node in todo.items():
            done(label, _run_one(work, label, node, settings))
    else:
        _in_processes(work, todo, settings, processes, done, show_bar)
    return [results[label] for label in nodes], from_cache


def _pool(processes: int) -> ProcessPoolExecutor:
    """Worker processes that die with this one (:mod:`quadest.app.parent_watch`)."""
    return ProcessPoolExecutor(max_workers=processes, mp_context=multiprocessing.get_context("spawn"), **pool_options())


def _in_processes(
    work: Work,
    todo: dict[str, dict],
    settings: RunSettings,
    processes: int,
    done: Callable[[str, Outcome], None],
    progress: bool,
) -> None:
    """Run ``todo`` in ``processes`` worker processes, handing each outcome to ``done`` as it comes
    (module docstring: a process that dies)."""
    missing = dict(todo)
    with _pool(processes) as pool:
        futures = {pool.submit(_run_one, work, label, node, settings): label for label, node in todo.items()}
        bar = tqdm(total=len(futures), desc="estimators", disable=None if progress else True, leave=False)
        for future in as_completed(futures):
            label = futures[future]
            try:
                outcome = future.result()
            except BrokenProcessPool:  # a process died: run what is missing alone, below
                continue
            except ConfigError:
                pool.shutdown(cancel_futures=True)
                raise
            except Exception as exc:  # e.g. a result that cannot be pickled back
                outcome = work.failed(label, f"{type(exc).__name__}: {exc}", settings), False
            done(label, outcome)
            del missing[label]
            bar.update()
        bar.close()
    for label, node in missing.items():
        with _pool(1) as pool:
            try:
                outcome = pool.submit(_run_one, work, label, node, settings).result()
            except ConfigError:
                raise
            except Exception as exc:  # its process died again: this estimator is the one
                outcome = work.failed(label, f"{type(exc).__name__}: {exc}", settings), False
        done(label, outcome)
