"""Range checks that a schema cannot express, run before any work starts.

Each failed check raises :class:`~quadest.errors.ConfigError` with one line naming the key, the
value and what is allowed. Types and unknown keys are already checked by the schemas at
composition, except keys added with ``+``, which :func:`~quadest.app.schema.check_known_keys`
rejects here.
"""

from __future__ import annotations

import dataclasses

from omegaconf import DictConfig

from quadest.app.estimator_runs import resolve_workers
from quadest.app.schema import ExperimentConf, check_known_keys, is_auto
from quadest.app.sequential_runs import validate_runs
from quadest.app.settings import JobSettings, job_settings
from quadest.app.sizing import check_size, duration_problem
from quadest.cache.location import validate_cache
from quadest.config.ranges import require_non_negative, require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.estimators.params import parameter_problem
from quadest.estimators.registry import discover as discover_estimators
from quadest.estimators.registry import resolve
from quadest.estimators.smoother_settings import smoother_settings
from quadest.evaluation.objective import validate_objective
from quadest.numerics.square_root import requested_kernels
from quadest.quadrotor.scenario_registry import discover as discover_scenarios
from quadest.replay.data import PX4_ROW, validate_replay
from quadest.sensors.noise_laws import check_noise_law
from quadest.sensors.registry import discover as discover_sensors
from quadest.simulation.registry import model_spec, state_dimension


def validate_run(experiment: ExperimentConf) -> None:
    validate_runs(experiment)  # runs=auto and decision.*
    if experiment.seed < 0:
        raise ConfigError("seed", experiment.seed, "must be an integer >= 0")
    require_positive("sample_period", experiment.sample_period, "must be > 0 seconds")
    problem = None if experiment.source is not None else duration_problem(experiment.duration, experiment.sample_period)
    if problem is not None:  # a replay's duration may be .inf: to the log's end
        raise ConfigError("duration", experiment.duration, problem)
    if not experiment.duration >= experiment.sample_period:
        raise ConfigError(
            "duration",
            experiment.duration,
            f"must be at least one sample period (sample_period={experiment.sample_period})",
        )
    require_positive("divergence_bound", experiment.divergence_bound)
    experiment.metrics.check()
    if experiment.workers < 0:
        allowed = "must be >= 0 (0: one process per estimator, up to the CPU count)"
        raise ConfigError("workers", experiment.workers, allowed)
    if experiment.output.saved_runs < 0:
        raise ConfigError("output.saved_runs", experiment.output.saved_runs, "must be >= 0")
    requested_kernels()  # QUADEST_KERNELS, the backend of the square-root numerics (docs/benchmarks.md)


def validate_model(settings: DataSettings) -> None:
    spec = model_spec(settings.model.name)  # an unknown name or a broken plugin: one line
    discover_sensors().refuse_selected(getattr(settings.model, "aiding", None) or [], key="model.aiding")
    spec.validate(settings)
    if spec.uses_quadrotor_groups:
        validate_sensor(settings)
        validate_scenario(settings)


def validate_sensor(settings: DataSettings) -> None:
    s = settings.sensor
    require_positive(
        "sensor.error_scale", s.error_scale, "must be > 0 (it also scales the white noise the filters rely on)"
    )
    for triad in ("accel", "gyro"):
        node = getattr(s, triad)
        for f in dataclasses.fields(node):
            if f.name == "noise_law":
                check_noise_law(f"sensor.{triad}.noise_law", node.noise_law)
            else:
                require_non_negative(f"sensor.{triad}.{f.name}", getattr(node, f.name))
        require_positive(
            f"sensor.{triad}.white_noise",
            node.white_noise,
            "must be > 0 (the filters' measurement covariance is built from it)",
        )
    if s.encoder.lines < 0:
        raise ConfigError("sensor.encoder.lines", s.encoder.lines, "must be >= 0 (0 disables quantisation)")
    require_non_negative("sensor.encoder.noise_std", s.encoder.noise_std)


def validate_scenario(settings: DataSettings) -> None:
    sc = settings.scenario
    found = discover_scenarios()
    found.refuse_selected([sc.name], key="scenario.name")
    if sc.name not in found.usable:
        raise ConfigError("scenario.name", sc.name, f"one of {sorted(found.usable)}")
    sc.validate()


def validate_estimators(experiment: ExperimentConf, settings: DataSettings) -> None:
    if not experiment.estimator:
        raise ConfigError("estimator", "[]", f"select at least one of {sorted(discover_estimators().usable)}")
    selected = {node.get("kind", label) for label, node in experiment.estimator.items()}
    discover_estimators().refuse_selected(selected, key="estimator")
    n = state_dimension(settings)
    for label, node in experiment.estimator.items():
        cls, params = resolve(label, node)
        problem = parameter_problem(getattr(cls, "Params", None), params, n)
        if problem is not None:
            key, value, allowed = problem
            raise ConfigError(f"estimator.{label}.{key}", value, allowed)
        if smoother_settings(label, node, cls) is not None and experiment.loop == "estimate":
            raise ConfigError(
                f"estimator.{label}.smoother",
                node.get("smoother"),
                "none with loop=estimate (each estimator flies its own truth; smooth with loop=truth or measured)",
            )


def validate_size(experiment: ExperimentConf, settings: DataSettings) -> None:
    """The job's memory floor against the machine's (:func:`quadest.app.sizing.check_size`); a
    ``runs=auto`` job is sized at its budget ``decision.max_runs``, the most runs it can hold."""
    nodes = experiment.estimator
    runs = experiment.decision.max_runs if is_auto(experiment.runs) else experiment.runs
    smoothers = sum(node.get("smoother", "none") != "none" for node in nodes.values())
    processes = resolve_workers(experiment.workers, len(nodes))
    check_size(runs, experiment.duration, experiment.sample_period, state_dimension(settings), len(nodes),
               processes, experiment.output.saved_runs, smoothers)  # fmt: skip


def check_labels(overrides: list[str]) -> None:
    """An estimator selected twice (``estimator=[srukf,srukf]``) would run once under one label:
    refused. A second copy takes a label of its own (``+estimator.srukf_b.kind=srukf``, docs/usage.md)."""
    for override in overrides:
        key, _, value = override.partition("=")
        if key.lstrip("+~") != "estimator" or not value.startswith("["):
            continue
        names = [v.strip() for v in value.strip("[]").split(",") if v.strip()]
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:
            raise ConfigError("estimator", value, f"{', '.join(twice)} selected twice (one label runs once); give a "
                              f"second copy a label of its own: +estimator.{twice[0]}_b.kind={twice[0]}")  # fmt: skip


def validate(cfg: DictConfig) -> JobSettings:
    """Check every range constraint of a composed config; raise :class:`ConfigError` on the first.

    Unknown keys and the model's name are checked on the composed config; then it is converted
    once into its typed settings (:func:`quadest.app.settings.job_settings`), which every other
    check reads and which are returned: what the job hands the layers below."""
    check_known_keys(cfg)
    model_spec(cfg.model.name)  # an unknown name or a broken plugin: one line, before the conversion
    settings = job_settings(cfg)
    experiment, data = settings.experiment, settings.data
    validate_run(experiment)
    validate_model(data)
    if experiment.source is not None:
        validate_replay(data, experiment.output.saved_runs)
        if PX4_ROW in experiment.estimator:  # truth_errors.csv names PX4's own estimate so
            raise ConfigError(f"estimator.{PX4_ROW}", PX4_ROW, f"a label other than '{PX4_ROW}' in a log replay "
                              "(PX4's own estimate is that row of truth_errors.csv)")  # fmt: skip
    validate_estimators(experiment, data)
    if experiment.source is None:  # a replay is one log of known length
        validate_size(experiment, data)
    validate_cache(experiment.cache)
    validate_objective(experiment.objective, list(experiment.estimator))
    return settings
