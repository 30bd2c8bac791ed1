"""One job: validate the config, convert it once into its typed settings
(:mod:`quadest.app.settings`), pick its kind, and run the one pipeline (:mod:`quadest.app.pipeline`).

The kinds: the open loop (:mod:`quadest.app.open_loop_job`), the closed loop (``loop`` ≠ ``open``,
:mod:`quadest.app.closed_loop_job`) and the flight-log replay (``source`` set,
:mod:`quadest.app.replay_job`). The output folder's layout is documented in ``docs/outputs.md``.
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig

from quadest.app.closed_loop_job import ClosedLoopJob
from quadest.app.open_loop_job import OpenLoopJob
from quadest.app.pipeline import JobKind, run_pipeline
from quadest.app.replay_job import ReplayJob
from quadest.app.schema import is_auto
from quadest.app.sequential_runs import run_until_decided
from quadest.app.settings import JobSettings
from quadest.app.validate import validate


def job_kind(settings: JobSettings) -> JobKind:
    """The kind of job ``settings`` ask for: a closed loop (``loop`` ≠ ``open``: the controller flies on
    truth, noisy states or each estimate, docs/closed-loop.md), a flight-log replay (``source``:
    differences to a reference, not errors, docs/replay.md), else the open loop. A closed loop's
    settings are checked here, before any work."""
    if settings.experiment.loop != "open":
        return ClosedLoopJob(settings)
    if settings.experiment.source is not None:
        return ReplayJob(settings)
    return OpenLoopJob(settings)


def run_job(cfg: DictConfig, out_dir: Path, overrides: list[str] | None = None) -> dict:
    """Validate the composed config ``cfg``, run the comparison and write every output into ``out_dir``.

    Returns the JSON summary. An estimator that raises (at construction or inside a run) is
    recorded as failed with the exception text; it does not stop the other estimators. With
    ``workers`` ≠ 1 the estimators run in separate processes on the same data (results do not
    depend on it: each estimator is deterministic given the data).
    """
    return run_validated(cfg, validate(cfg), out_dir, overrides)


def run_validated(cfg: DictConfig, settings: JobSettings, out_dir: Path, overrides: list[str] | None = None) -> dict:
    """:func:`run_job` of a config already validated into ``settings`` (:func:`~quadest.app.validate.validate`)."""
    if is_auto(settings.experiment.runs):
        return run_until_decided(settings, cfg, out_dir, overrides)
    return run_pipeline(job_kind(settings), settings, cfg, out_dir, overrides)
