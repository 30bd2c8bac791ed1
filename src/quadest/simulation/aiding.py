"""The further sensors of a model option (``model.aiding``), whatever they are: their settings
from the config, their checks, their samples and the filters' models of them (docs/sensors.md).

Every sensor goes through the same three calls, so no model knows a sensor by name:

- :func:`validate_aiding`: the names are registered sensors (:mod:`quadest.sensors.registry`),
  each at most once; a broken sensor, or one of two with one name, is refused with its one line
  (:meth:`quadest.config.registry.Found.refuse_selected`); the model offers every
  quantity the sensor measures; the sensor's own checks of its settings;
- :func:`measure_aiding`: each sensor, in ``model.aiding`` order, simulates its samples of the
  truth from its own random streams (a built-in's from :data:`~quadest.montecarlo.streams.STREAMS`
  where it names them there, any other from streams named after it,
  :func:`~quadest.montecarlo.streams.named_streams`), then
  gives the filters its model on the model's :class:`~quadest.sensors.base.StateLayout`.

The settings of each sensor (its node ``sensor.<name>``, or the sensor's ``settings_key``, as an
instance of its ``Settings``) come made: the application layer converts them with the rest of
the config (:func:`quadest.app.settings.aiding_settings`) into
:attr:`DataSettings.aiding <quadest.config.settings.DataSettings.aiding>`.
"""

from __future__ import annotations

from typing import Any

from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.montecarlo.streams import named_streams
from quadest.sensors.base import Sensor, SensorContext, SensorModel, StateLayout, TrueMotion
from quadest.sensors.record import SensorRecord
from quadest.sensors.registry import discover, is_builtin


def sensor_settings(settings: DataSettings, name: str) -> Any:
    """The settings of sensor ``name`` of ``model.aiding`` (an instance of its ``Settings``), or
    ``None`` if the config has no node for them."""
    return settings.aiding.get(name)


def sensor_context(settings: DataSettings, calibrated: bool, noise_inflation: float) -> SensorContext:
    """The job settings the sensors read (:class:`~quadest.sensors.base.SensorContext`): the Monte
    Carlo settings and the MIMU's error scale from ``settings``; whether the filters know each run's
    sensor errors and the factor on every ``R`` from the model, which passes its own keys (the
    quadrotor's and the INS's ``model.calibrated`` and ``model.measurement_noise_inflation``)."""
    return SensorContext(
        sample_period=float(settings.sample_period),
        duration=float(settings.duration),
        error_scale=float(settings.sensor.error_scale),
        calibrated=bool(calibrated),
        noise_inflation=float(noise_inflation),
    )


def _selected(settings: DataSettings) -> dict[str, type[Sensor]]:
    """The sensor classes of ``model.aiding`` in order; one-line errors for unknown, repeated or
    broken ones."""
    names = list(settings.model.aiding)
    found = discover()
    found.refuse_selected(names, key="model.aiding")
    sensors = found.usable
    for name in names:
        if name not in sensors or names.count(name) > 1:
            raise ConfigError("model.aiding", names, f"distinct names from {sorted(sensors)}")
    return {name: sensors[name] for name in names}


def validate_aiding(settings: DataSettings, layout: StateLayout) -> None:
    """Check ``model.aiding`` against the sensors and the model's ``layout`` before any work
    (module docstring); raise :class:`ConfigError` on the first problem."""
    names = list(settings.model.aiding)
    for name, cls in _selected(settings).items():
        missing = [q for q in cls.measures if q not in layout.quantities]
        if missing:
            raise ConfigError(
                "model.aiding",
                names,
                f"sensor '{name}' measures {', '.join(missing)}, which model={settings.model.name} does not estimate "
                f"(it offers {', '.join(layout.quantities) or 'none'})",
            )
        own = sensor_settings(settings, name)
        if own is None:
            raise ConfigError(
                "model.aiding",
                names,
                f"sensor '{name}' reads its settings from {cls.key()}, which is not in the config",
            )
        cls.validate(own, cls.key(), float(settings.sample_period))


def measure_aiding(
    settings: DataSettings, truth: TrueMotion, streams: dict[str, list], layout: StateLayout, context: SensorContext
) -> tuple[dict[str, SensorRecord], dict[str, SensorModel]]:
    """The samples of every sensor of ``model.aiding`` and the filters' models of them, by
    name in update order, each sensor made with ``context`` (:func:`sensor_context`). ``streams``
    are the runs' streams (:func:`~quadest.montecarlo.streams.run_streams`): a built-in sensor draws
    from those it names; every other stream, all of a plugin's and a new in-repository sensor's, is
    named after the sensor (``sensor:<name>:<stream>``)."""
    runs, seed, first_run = truth.position.shape[0], int(settings.seed), settings.first_run
    records, models = {}, {}
    for name, cls in _selected(settings).items():
        sensor = cls(sensor_settings(settings, name), context)
        own = {
            s: streams[s]
            if is_builtin(cls) and s in streams
            else named_streams(seed, runs, f"sensor:{name}:{s}", first_run)
            for s in cls.stream_names()
        }
        records[name] = sensor.simulate(truth, own)
        models[name] = sensor.measurement_model(layout)
    return records, models
