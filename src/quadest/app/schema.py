"""Structured-config schemas: every config node has a dataclass, so that a misspelled key or a
value of the wrong type fails when Hydra composes the config, before any work starts.

The tree mirrors the package: ``model/`` (each option's :class:`~quadest.simulation.spec.ModelSpec`,
:mod:`quadest.simulation.registry`), ``sensor/`` (:mod:`quadest.sensors`, a plugin sensor's
settings included: :func:`sensor_schema`), ``scenario/`` (:mod:`quadest.quadrotor.scenarios`), ``estimator/``
(:mod:`quadest.estimators`). Each YAML option pulls its schema from ``/schema/<group>/<name>``.
Each feature keeps its own schema dataclasses; this module assembles them into the root
:class:`ExperimentConf` and stores them in Hydra's ConfigStore (:func:`register_schemas`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, DictConfig, OmegaConf

from quadest.cache.location import CacheConf
from quadest.config.closed_loop import ClosedLoopConf
from quadest.config.registry import missing_yaml
from quadest.errors import ConfigError, PluginError
from quadest.estimators.registry import discover as discover_estimators
from quadest.evaluation.objective import ObjectiveConf
from quadest.metrics.settings import MetricsConf
from quadest.quadrotor.scenario_registry import discover as discover_scenarios
from quadest.replay.data import SourceConf
from quadest.sensors.barometer import BarometerSpec
from quadest.sensors.gps import GPSSpec
from quadest.sensors.mimu import TriadSpec
from quadest.sensors.noise_laws import NoiseLaw
from quadest.sensors.registry import discover as discover_sensors
from quadest.sensors.registry import sensor_classes
from quadest.sensors.vision import VisionSpec
from quadest.simulation.registry import discover as discover_models


@dataclass
class EncoderConf:
    """Rotor encoders: lines per revolution (0: no quantisation) and white noise (rad/s)."""

    lines: int = 256
    noise_std: float = 0.0


@dataclass
class TriadConf(TriadSpec):
    """``sensor.accel`` / ``sensor.gyro``: the error levels and the law of the white noise."""

    noise_law: NoiseLaw = field(default_factory=NoiseLaw)


@dataclass
class SensorConf:
    """``sensor=ideal|tactical|consumer``; ``error_scale`` multiplies every MIMU error term."""

    name: str = MISSING
    error_scale: float = 1.0
    accel: TriadConf = field(default_factory=TriadConf)
    gyro: TriadConf = field(default_factory=TriadConf)
    encoder: EncoderConf = field(default_factory=EncoderConf)
    gps: GPSSpec = field(default_factory=GPSSpec)  # navigation sensors (model=ins): conf/sensor/gps/ ...
    barometer: BarometerSpec = field(default_factory=BarometerSpec)
    vision: VisionSpec = field(default_factory=VisionSpec)


@dataclass
class OutputConf:
    """What a job writes besides the metrics: time series of the first ``saved_runs`` runs and
    figures of run 0 (with ``per_estimator_figures``, also truth vs estimate per estimator)."""

    saved_runs: int = 3
    figures: bool = True
    per_estimator_figures: bool = False


AUTO = "auto"
"""The value of ``runs`` that runs until every comparison decides (:class:`DecisionConf`)."""


def is_auto(runs: int | str) -> bool:
    """Whether ``runs`` asks for a job that runs until its comparisons decide."""
    return isinstance(runs, str) and runs == AUTO


@dataclass
class DecisionConf:
    """How a ``runs=auto`` job decides its comparisons (:mod:`quadest.app.sequential_runs`,
    docs/experiments.md): runs added ``batch`` at a time up to ``max_runs`` (a multiple of
    ``batch``), intervals with α-spending at family level ``1 − alpha``, *equivalent* inside
    ``±margin`` %, and the comparisons ``pairs`` (``"estimator - reference"``; ``None``: every
    estimator against the first)."""

    batch: int = 50
    max_runs: int = 500
    alpha: float = 0.05
    margin: float = 1.0
    pairs: list[str] | None = None


@dataclass
class ExperimentConf:
    """The root config: Monte Carlo settings plus the four groups."""

    runs: int | str = 50  # or "auto": add runs until every comparison decides (``decision``)
    seed: int = 2026
    duration: float = 20.0
    sample_period: float = 0.01
    divergence_bound: float = 50.0
    progress: bool = True
    workers: int = 0
    model: Any = MISSING
    sensor: SensorConf = MISSING
    scenario: Any = MISSING
    estimator: dict[str, Any] = field(default_factory=dict)
    output: OutputConf = field(default_factory=OutputConf)
    sweep: dict[str, Any] = field(default_factory=dict)  # values a sweep varies and configs interpolate
    objective: ObjectiveConf = field(default_factory=ObjectiveConf)  # set by conf/hparams_search/
    cache: CacheConf = field(default_factory=CacheConf)
    loop: str = "open"  # open | truth | measured | estimate: what the controller flies on (docs/closed-loop.md)
    closed_loop: ClosedLoopConf = field(default_factory=ClosedLoopConf)
    source: SourceConf | None = None  # a flight log instead of the simulation (conf/experiment/px4_replay.yaml)
    decision: DecisionConf = field(default_factory=DecisionConf)
    metrics: MetricsConf = field(default_factory=MetricsConf)  # windows of the windowed measures (docs/metrics.md)


def check_known_keys(cfg: DictConfig, prefix: str = "") -> None:
    """Raise :class:`ConfigError` naming the first key of a schema-typed node that its schema does
    not declare.

    Hydra composes the root in struct mode, so ``bogus_key=1`` already fails, but an override with
    ``+`` (``+bogus_key=1``) is added by design in an open dict and survives composition. Nodes
    without a dataclass schema (``estimator``, ``sweep``, a plugin's free-form node) may hold any
    key; their typed children are still checked.
    """
    schema = OmegaConf.get_type(cfg)
    declared = {f.name for f in dataclasses.fields(schema)} if dataclasses.is_dataclass(schema) else None
    for key in cfg.keys():
        child = cfg._get_node(key)
        line = registry_line(str(key), str(child._value()), group_found=False) if "/" in str(key) else None
        if line is not None:  # a config group Hydra did not find, taken for a key
            raise PluginError(str(child._value()), line, key=f"{prefix}{key}")
        if declared is not None and key not in declared:
            raise ConfigError(
                f"{prefix}{key}",
                child._value(),
                f"not a key of {schema.__name__}; allowed keys: {', '.join(sorted(declared))}",
            )
        if isinstance(child, DictConfig):
            check_known_keys(child, f"{prefix}{key}.")


def registry_line(group: str, name: str, group_found: bool = True) -> str | None:
    """The registry's line for option ``name`` of config group ``group`` that Hydra could not load
    (``estimator/<name>``, ``model/<name>``, ``scenario/<name>``, their ``schema/`` nodes,
    ``sensor/<sensor>/<name>``):
    the problem of a refused extension, or, for a registered one, that its YAML is not on the search
    path (:mod:`quadest.config.registry`); ``None`` for a name no registry knows. A sensor's options
    sit in a group of their own, which Hydra lists when it finds the group (``group_found``)."""
    registries = {
        "estimator": discover_estimators,
        "model": discover_models,
        "scenario": discover_scenarios,
        "sensor": discover_sensors,
    }
    kind, _, sensor = group.removeprefix("schema/").partition("/")
    if kind not in registries or (kind == "sensor") != bool(sensor):
        return None
    found, extension = registries[kind](), sensor or name
    if extension in found.problems and extension not in found.usable:
        return found.problems[extension]
    if extension in found.usable and (group == kind or (group == f"sensor/{sensor}" and not group_found)):
        return missing_yaml(found, extension, f"{group}/{name}.yaml")
    return None


def sensor_schema() -> type:
    """The schema of the ``sensor`` node: :class:`SensorConf` (the MIMU, the encoders and the
    built-in navigation sensors), plus a field ``<name>`` for each registered plugin sensor whose
    settings live at ``sensor.<name>`` (docs/sensors.md), with its ``Settings`` defaults."""
    declared = {f.name for f in dataclasses.fields(SensorConf)}
    extra = [
        (name, cls.Settings, field(default_factory=cls.Settings))
        for name, cls in sensor_classes().items()
        if cls.key() == f"sensor.{name}" and name not in declared
    ]
    return dataclasses.make_dataclass("SensorConf", extra, bases=(SensorConf,)) if extra else SensorConf


def model_default(model_name: str, key: str, fallback: float) -> float:
    """``${model_default:${model.name},KEY,FALLBACK}`` in ``conf/config.yaml``: the model option's
    own default of the job key ``KEY`` (:attr:`~quadest.simulation.spec.ModelSpec.job_defaults`),
    else ``FALLBACK``; an experiment or a command-line value replaces the whole interpolation."""
    spec = discover_models().usable.get(model_name)
    return float(spec.job_defaults.get(key, fallback)) if spec is not None else float(fallback)


def register_schemas() -> None:
    """Store every schema in Hydra's ConfigStore and the ``model_default`` resolver (idempotent)."""
    OmegaConf.register_new_resolver("model_default", model_default, replace=True)
    cs = ConfigStore.instance()
    cs.store(name="experiment_schema", node=ExperimentConf)
    models = discover_models()
    for name, spec in models.usable.items():
        cs.store(group="schema/model", name=name, node=spec.schema)
    for name in set(models.problems) - set(models.usable):  # composes, so that the pre-run check names the problem
        cs.store(group="schema/model", name=name, node={"name": name})
    cs.store(group="schema/sensor", name="sensor", node=sensor_schema())
    for name, cls in discover_scenarios().usable.items():
        cs.store(group="schema/scenario", name=name, node=cls)
    estimators = discover_estimators()
    for name, spec in estimators.usable.items():
        cs.store(group="schema/estimator", name=name, node=spec.params)
    for name in set(estimators.problems) - set(estimators.usable):  # as a refused model's
        cs.store(group="schema/estimator", name=name, node={"kind": name})
