"""The composed config, converted once into the typed settings the layers below take.

Hydra composes a :class:`~omegaconf.DictConfig` whose nodes carry their schemas
(:mod:`quadest.app.schema`). The application layer validates it (:func:`quadest.app.validate.validate`)
and converts it here, once per job, into :class:`JobSettings`:

- :attr:`JobSettings.experiment`: the root :class:`~quadest.app.schema.ExperimentConf`, every node
  an instance of its schema dataclass (``OmegaConf.to_object``), the estimators' nodes as resolved
  plain dicts (label → node; an estimator takes its own node, :mod:`quadest.estimators.registry`);
- :attr:`JobSettings.data`: the :class:`~quadest.config.settings.DataSettings` the data builders,
  the closed loop and the replay read, with the settings of every further sensor of
  ``model.aiding`` made here (the one conversion of a sensor node into its ``Settings``).

Each layer is handed its own part: a data builder the :class:`DataSettings`, the result cache the
:class:`~quadest.app.schema.CacheConf` and the data key (:func:`data_key`, computed here from the
resolved config, as before), the tuning objective its :class:`~quadest.app.schema.ObjectiveConf`.
No module below this layer imports OmegaConf or reads raw config keys (docs/layout.md).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from omegaconf import DictConfig, ListConfig, OmegaConf

from quadest.app.schema import ExperimentConf, SensorConf, is_auto
from quadest.cache.keys import module_digest, plugin_digest, resolved_data_key
from quadest.config.settings import DataSettings
from quadest.sensors.base import Sensor
from quadest.sensors.registry import sensor_classes
from quadest.simulation.registry import model_spec


@dataclass
class JobSettings:
    """One job's config, typed (module docstring)."""

    experiment: ExperimentConf
    data: DataSettings


def job_settings(cfg: DictConfig) -> JobSettings:
    """The typed settings of the composed config ``cfg`` (checked for unknown keys and an unknown
    or broken model already: :func:`quadest.app.validate.validate`)."""
    experiment = experiment_settings(cfg)
    return JobSettings(experiment, _data_settings(experiment, aiding_settings(cfg)))


def data_settings(cfg: DictConfig) -> DataSettings:
    """The :class:`DataSettings` of ``cfg`` alone (what a data builder takes; the tests' way in)."""
    return job_settings(cfg).data


def experiment_settings(cfg: DictConfig) -> ExperimentConf:
    """The root of ``cfg`` as an :class:`ExperimentConf`: each node converted with
    ``OmegaConf.to_object`` (interpolations resolved; a node with a schema becomes an instance of
    it), ``estimator`` as label → resolved plain dict. A key the config lacks keeps its default."""
    values: dict[str, Any] = {}
    for f in dataclasses.fields(ExperimentConf):
        if f.name not in cfg:
            continue
        if f.name == "estimator":
            values[f.name] = {
                str(label): OmegaConf.to_container(node, resolve=True) for label, node in cfg.estimator.items()
            }
            continue
        value = cfg[f.name]
        values[f.name] = OmegaConf.to_object(value) if isinstance(value, DictConfig | ListConfig) else value
    return ExperimentConf(**values)


def _data_settings(experiment: ExperimentConf, aiding: dict[str, Any]) -> DataSettings:
    sensor = experiment.sensor
    if dataclasses.is_dataclass(sensor) and type(sensor) is not SensorConf:
        # the schema with plugin sensors' fields (schema.sensor_schema) is made at run time and does
        # not pickle into worker processes; those sensors' settings are in ``aiding``
        sensor = SensorConf(**{f.name: getattr(sensor, f.name) for f in dataclasses.fields(SensorConf)})
    return DataSettings(
        runs=experiment.decision.batch if is_auto(experiment.runs) else experiment.runs,  # runs=auto: a batch
        seed=experiment.seed,
        duration=experiment.duration,
        sample_period=experiment.sample_period,
        model=experiment.model,
        sensor=sensor,
        scenario=experiment.scenario,
        loop=experiment.loop,
        closed_loop=experiment.closed_loop,
        source=experiment.source,
        aiding=aiding,
    )


def aiding_settings(cfg: DictConfig) -> dict[str, Any]:
    """Each registered sensor of ``cfg.model.aiding`` → an instance of its ``Settings`` from its
    settings node (``sensor.<name>`` or its ``settings_key``; ``None`` if the config has none).
    An unknown or broken sensor is left out: :func:`quadest.simulation.aiding.validate_aiding` names it."""
    sensors = sensor_classes()
    names = list(cfg.model.get("aiding") or []) if isinstance(cfg.model, DictConfig) else []
    return {name: sensor_settings(cfg, sensors[name]) for name in names if name in sensors}


def sensor_settings(cfg: DictConfig, cls: type[Sensor]) -> Any:
    """The instance of ``cls.Settings`` at ``cls.key()`` in ``cfg`` (``None`` if there is no such
    node)."""
    node = OmegaConf.select(cfg, cls.key())
    if not isinstance(node, DictConfig):
        return None
    if OmegaConf.get_type(node) is not cls.Settings:
        node = OmegaConf.merge(OmegaConf.structured(cls.Settings), node)
    return OmegaConf.to_object(node)


def data_key(cfg: DictConfig) -> str | None:
    """Key of the Monte Carlo data of job config ``cfg`` (:func:`quadest.cache.keys.resolved_data_key`
    of the resolved config and of the source of the model and sensor plugins it uses); ``None``, so
    that the job is not cached, when a plugin's source cannot be read."""
    return _data_key(cfg, {})


def batch_data_key(cfg: DictConfig, runs: int, first_run: int) -> str | None:
    """:func:`data_key` of the batch of ``runs`` runs from run ``first_run`` on of a ``runs=auto``
    job ``cfg``: the key of the job with ``runs`` runs, plus ``first_run`` when it is not 0, so
    that the first batch is the job of ``runs`` runs (docs/cache.md)."""
    return _data_key(cfg, {"runs": int(runs), **({"first_run": int(first_run)} if first_run else {})})


def _data_key(cfg: DictConfig, replaced: dict[str, Any]) -> str | None:
    plugins = plugin_digests(cfg)
    if any(digest is None for digest in plugins.values()):
        return None
    resolved = {**OmegaConf.to_container(cfg, resolve=True), **replaced}
    return resolved_data_key(resolved, {k: v for k, v in plugins.items() if v})


def plugin_digests(cfg: DictConfig) -> dict[str, str | None]:
    """:func:`quadest.cache.keys.module_digest` of the code of the model (``"model"``: the modules of
    its spec's ``build`` and ``schema``) and of each sensor of ``model.aiding``
    (``"sensor.<name>"``): ``""`` for the package's own."""
    spec = model_spec(cfg.model.name)
    modules = {getattr(spec.build, "__module__", None) or spec.schema.__module__, spec.schema.__module__}
    digests = {module_digest(m) for m in modules}
    found: dict[str, str | None] = {"model": None if None in digests else "".join(sorted(digests))}
    sensors = sensor_classes()
    for name in list(cfg.model.get("aiding") or []) if isinstance(cfg.model, DictConfig) else []:
        if name in sensors:
            found[f"sensor.{name}"] = plugin_digest(sensors[name])
    return found
