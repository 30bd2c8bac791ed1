"""The Python API: the job the ``quadest`` command runs, step by step (``docs/python-api.md``).

``quadest`` exports these names (``import quadest; quadest.compose([...])``). Each is a thin
facade over the job's own code, so that a result from Python is the command's result:

- :func:`compose`: the config from the same YAML tree, overrides and checks as the command
  (:func:`quadest.app.validate.validate`), as a :class:`ValidatedConfig`;
- :func:`make_data`: the filter model and its Monte Carlo data (``data.model`` is the model);
- :func:`run_estimators`: every selected estimator on that data, on the same draws;
- :func:`tables`: the metric tables of ``metrics.csv``, ``rmse_summary.csv`` and the paired
  comparison, as data frames;
- :func:`run_job`: the whole job with every output file, as ``quadest`` writes it.

The step functions run the open loop (simulated data, errors against its truth) with a number of
runs; :func:`run_job` runs every kind (closed loop, replay, ``runs=auto``). Data and results go
through the result cache as in a job (``cache.enabled``, ``docs/cache.md``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from hydra import compose as compose_hydra
from hydra import initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.errors import HydraException
from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from quadest.app.cli import one_line
from quadest.app.estimator_runs import run_estimators as run_each_estimator
from quadest.app.job import run_validated
from quadest.app.open_loop_job import OpenLoopJob
from quadest.app.pipeline import estimator_params, job_cache, run_settings, table_rows
from quadest.app.schema import is_auto, register_schemas
from quadest.app.settings import JobSettings
from quadest.app.validate import check_labels, validate
from quadest.config.paths import config_dir
from quadest.errors import ConfigError
from quadest.evaluation.job_tables import MetricTables
from quadest.evaluation.pcrlb import pcrlb_variances
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.results import EstimatorResult


@dataclass(frozen=True)
class ValidatedConfig:
    """A job's config, composed and checked (:func:`compose`): what every other function takes."""

    composed: DictConfig
    """The composed config, as the command composes it (a job writes it as ``config.yaml``)."""
    settings: JobSettings
    """The same config, typed (:mod:`quadest.app.settings`): ``settings.experiment.runs`` etc."""
    overrides: tuple[str, ...]
    """The overrides it was composed with."""


def compose(overrides: Sequence[str] = ()) -> ValidatedConfig:
    """The config of ``quadest <overrides>``: the root config of ``conf/`` with ``overrides``
    (Hydra's syntax, e.g. ``["model=ungm", "estimator=[ekf,iekf]", "runs=20"]``), checked as the
    command checks it, before any work.

    Hydra's global state is cleared first (as the command does before it starts).

    Raises:
        ConfigError: one line naming the key, the value and what is allowed: a value out of range,
            an unknown key or group option, or a value of the wrong type.
    """
    overrides = list(overrides)
    check_labels(overrides)
    composed = compose_unchecked(overrides)
    return ValidatedConfig(composed, validate(composed), tuple(overrides))


def compose_unchecked(overrides: Sequence[str] = ()) -> DictConfig:
    """The root config of ``conf/`` with ``overrides``, as Hydra composes it, before the range
    checks of :func:`compose`: for a test that hands a refused value to the check it tests.

    Raises:
        ConfigError: an unknown key or group option, or a value of the wrong type (one line).
    """
    overrides = list(overrides)
    register_schemas()
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
            return compose_hydra(config_name="config", overrides=overrides)
    except (HydraException, OmegaConfBaseException) as exc:
        raise composition_error(exc, overrides) from None


def composition_error(exc: Exception, overrides: list[str]) -> ConfigError:
    """Hydra's or OmegaConf's error composing ``overrides`` as a :class:`ConfigError` with the
    command's one line (:func:`quadest.app.cli.one_line`) and the offending key: OmegaConf's
    ``full_key`` (an unknown key, a value of the wrong type), else the group of an option Hydra
    could not find (``model``, ``estimator``)."""
    message = one_line(exc)
    cause = exc.__cause__ or exc.__context__
    key = getattr(exc, "full_key", None) or getattr(cause, "full_key", None)
    missing = re.search(r"Could not (?:load|find) '([\w/]+)/([^']+)'", message)
    if key:
        given = [value for name, _, value in (o.lstrip("+~").partition("=") for o in overrides) if name == key]
        return ConfigError(str(key), given[-1] if given else None, message)
    if missing:
        return ConfigError(missing[1].replace("/", "."), missing[2], message)
    return ConfigError("overrides", overrides, message)


def open_loop(config: ValidatedConfig) -> OpenLoopJob:
    """The open-loop job of ``config``, which the step functions run.

    Raises:
        ConfigError: ``config`` asks for a closed loop, a replay or ``runs=auto`` (:func:`run_job`
            runs those).
    """
    exp = config.settings.experiment
    if exp.loop != "open":
        raise ConfigError("loop", exp.loop, "open for the step functions; quadest.run_job runs a closed loop")
    if exp.source is not None:
        raise ConfigError("source", exp.source, "null for the step functions; quadest.run_job runs a replay")
    if is_auto(exp.runs):
        raise ConfigError("runs", exp.runs, "a number for the step functions; quadest.run_job runs runs=auto")
    return OpenLoopJob(config.settings)


def make_data(config: ValidatedConfig) -> MonteCarloData:
    """The Monte Carlo data of ``config``: its filter model (``data.model``), truth, inputs and
    measurements of ``runs`` runs, drawn from ``seed`` (from the result cache if it holds them)."""
    job = open_loop(config)
    return job_cache(config.settings, config.composed).data(job.make_data)[0]


def run_estimators(config: ValidatedConfig, data: MonteCarloData) -> list[EstimatorResult]:
    """Every estimator of ``config`` run on ``data`` (:func:`make_data`), in the config's order,
    with the job's cache, worker processes and failure isolation: an estimator that raises is a
    failed result (every run flagged with the reason), not an exception."""
    job, settings = open_loop(config), config.settings
    exp = settings.experiment
    cache = job_cache(settings, config.composed)
    results, _ = run_each_estimator(job.work(data), exp.estimator, cache, run_settings(settings, int(exp.runs)),
                                    int(exp.workers))  # fmt: skip
    return results


def tables(config: ValidatedConfig, data: MonteCarloData, results: list[EstimatorResult]) -> MetricTables:
    """The metric tables of ``results`` (:func:`run_estimators` on ``data``), with a smoother's
    rows: ``.table`` per run, state and measure (``metrics.csv``), ``.summary`` over the runs
    (``rmse_summary.csv``), ``.printed`` the table the command prints, ``.paired`` the paired
    comparison (``paired_comparison.csv``); columns in ``docs/outputs.md``."""
    job, settings = open_loop(config), config.settings
    rows = table_rows(results, estimator_params(settings.experiment.estimator), {})
    bound = job_cache(settings, config.composed).derived("pcrlb", lambda: pcrlb_variances(data))
    return job.tables(data, rows, bound)


def run_job(config: ValidatedConfig, out_dir: str | Path) -> dict:
    """The whole job of ``config``, as ``quadest`` runs it: every output written into ``out_dir``
    (``docs/outputs.md``); returns the contents of ``summary.json``."""
    return run_validated(config.composed, config.settings, Path(out_dir), list(config.overrides))
