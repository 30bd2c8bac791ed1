"""The further sensors of a model option (``model.aiding``), whatever they are: their settings
from the config, their checks, their samples and the filters' models of them (docs/sensors.md).

Every sensor goes through the same three calls, so no model knows a sensor by name:

- :func:`validate_aiding`: the names are registered sensors (:mod:`quadest.sensors.registry`),
  each at most once; a broken plugin is refused with its one line; the model offers every
  quantity the sensor measures; the sensor's own checks of its settings;
- :func:`measure_aiding`: each sensor, in ``model.aiding`` order, simulates its samples of the
  truth from its own random streams (a built-in's from :data:`~quadest.montecarlo.streams.STREAMS`
  where it names them there, any other from streams named after it,
  :func:`~quadest.montecarlo.streams.named_streams`), then
  gives the filters its model on the model's :class:`~quadest.sensors.base.StateLayout`.

The settings node of a sensor (``sensor.<name>``, or the sensor's ``settings_key``) becomes an
instance of its ``Settings`` with ``OmegaConf.to_object``: the one use of OmegaConf below the
application layer (docs/layout.md).
"""

from __future__ import annotations

import sys
from typing import Any

from omegaconf import DictConfig, OmegaConf

from quadest.errors import ConfigError, PluginError
from quadest.montecarlo.streams import named_streams
from quadest.sensors.base import Sensor, SensorContext, SensorModel, StateLayout, TrueMotion
from quadest.sensors.record import SensorRecord
from quadest.sensors.registry import discover, is_builtin

_warned: set[str] = set()


def sensor_settings(cfg: Any, cls: type[Sensor]) -> Any:
    """The instance of ``cls.Settings`` at ``cls.key()`` in ``cfg`` (``None`` if there is no such
    node)."""
    node = OmegaConf.select(cfg, cls.key())
    if not isinstance(node, DictConfig):
        return None
    if OmegaConf.get_type(node) is not cls.Settings:
        node = OmegaConf.merge(OmegaConf.structured(cls.Settings), node)
    return OmegaConf.to_object(node)


def sensor_context(cfg: Any) -> SensorContext:
    """The job settings the sensors read (:class:`~quadest.sensors.base.SensorContext`); a model
    without ``calibrated`` or ``measurement_noise_inflation`` gets ``True`` and 1."""
    return SensorContext(
        sample_period=float(cfg.sample_period),
        duration=float(cfg.duration),
        error_scale=float(cfg.sensor.error_scale),
        calibrated=bool(cfg.model.get("calibrated", True)),
        noise_inflation=float(cfg.model.get("measurement_noise_inflation", 1.0)),
    )


def report_plugin_problems(selected: list[str]) -> None:
    """Refuse a selected broken sensor plugin; mention the others once per process on stderr
    (as :func:`quadest.estimators.registry.report_plugin_problems`)."""
    sensors, problems = discover()
    for name, message in problems.items():
        if name in selected and name not in sensors:
            raise PluginError(name, message, key="model.aiding")
        if message not in _warned:
            _warned.add(message)
            print(f"quadest: warning: {message}", file=sys.stderr)


def _selected(cfg: Any) -> dict[str, type[Sensor]]:
    """The sensor classes of ``cfg.model.aiding`` in order; one-line errors for unknown, repeated
    or broken ones."""
    names = list(cfg.model.aiding)
    report_plugin_problems(names)
    sensors = discover()[0]
    for name in names:
        if name not in sensors or names.count(name) > 1:
            raise ConfigError("model.aiding", names, f"distinct names from {sorted(sensors)}")
    return {name: sensors[name] for name in names}


def validate_aiding(cfg: Any, layout: StateLayout) -> None:
    """Check ``cfg.model.aiding`` against the sensors and the model's ``layout`` before any work
    (module docstring); raise :class:`ConfigError` on the first problem."""
    names = list(cfg.model.aiding)
    for name, cls in _selected(cfg).items():
        missing = [q for q in cls.measures if q not in layout.quantities]
        if missing:
            raise ConfigError(
                "model.aiding",
                names,
                f"sensor '{name}' measures {', '.join(missing)}, which model={cfg.model.name} does not estimate "
                f"(it offers {', '.join(layout.quantities) or 'none'})",
            )
        settings = sensor_settings(cfg, cls)
        if settings is None:
            raise ConfigError(
                "model.aiding",
                names,
                f"sensor '{name}' reads its settings from {cls.key()}, which is not in the config",
            )
        cls.validate(settings, cls.key(), float(cfg.sample_period))


def measure_aiding(
    cfg: Any, truth: TrueMotion, streams: dict[str, list], layout: StateLayout
) -> tuple[dict[str, SensorRecord], dict[str, SensorModel]]:
    """The samples of every sensor of ``cfg.model.aiding`` and the filters' models of them, by
    name in update order. ``streams`` are the runs' streams (:func:`~quadest.montecarlo.streams.run_streams`):
    a built-in sensor draws from those it names; every other stream, all of a plugin's and a new
    in-repository sensor's, is named after the sensor (``sensor:<name>:<stream>``)."""
    context = sensor_context(cfg)
    runs, seed = truth.position.shape[0], int(cfg.seed)
    records, models = {}, {}
    for name, cls in _selected(cfg).items():
        sensor = cls(sensor_settings(cfg, cls), context)
        own = {
            s: streams[s] if is_builtin(cls) and s in streams else named_streams(seed, runs, f"sensor:{name}:{s}")
            for s in cls.stream_names()
        }
        records[name] = sensor.simulate(truth, own)
        models[name] = sensor.measurement_model(layout)
    return records, models
