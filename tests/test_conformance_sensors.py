"""``quadest.conformance.check_sensor``: every built-in sensor and the plugin sensors of
docs/sensors.md pass it; a sensor with a wrong Jacobian, one drawing from numpy's global generator, one drawing
every run from one generator, one ignoring its streams and one sampling off its rate each fail it,
on the check that names their bug."""

from __future__ import annotations

import importlib.util
import sys
from dataclasses import dataclass

import numpy as np
import pytest

from plugin_site import PLUGINS
from quadest.conformance import check_sensor
from quadest.sensors.record import SensorRecord
from quadest.sensors.registry import sensor_classes


def _plugin_module(name: str):
    """``tests/plugins/<name>.py``, loaded under a name of its own (the plugin tests import it
    from their fake site)."""
    spec = importlib.util.spec_from_file_location(f"conformance_{name}", PLUGINS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


rangefinder = _plugin_module("rangefinder_sensor")
Rangefinder = rangefinder.Rangefinder


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(sensor_classes()))
def test_every_builtin_sensor_conforms(name):
    check_sensor(sensor_classes()[name])


@pytest.mark.slow
def test_the_plugin_sensors_of_the_docs_conform():
    """The rangefinder of docs/sensors.md and the velocity sensor its quadrotor section names."""
    check_sensor(Rangefinder)
    check_sensor(_plugin_module("velocimeter_sensor").Velocimeter)


@dataclass
class TiltedAiding(rangefinder.RangefinderAiding):
    """The Jacobian 0.1 % too large: a wrong lever arm or scale, not a wrong sign."""

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return 1.001 * super().jacobian(x, u)


class WrongJacobian(Rangefinder):
    def measurement_model(self, layout):
        return TiltedAiding(self.context.noise_inflation * self.settings.noise**2 * np.eye(1), layout)


class GlobalDraws(Rangefinder):
    """Noise from numpy's global generator: adding it changes every later global draw."""

    def simulate(self, truth, streams):
        record = super().simulate(truth, streams)
        noise = np.random.standard_normal(record.values.shape) * self.settings.noise
        return SensorRecord(record.values + noise, record.available)


class OneGenerator(Rangefinder):
    """Every run's noise from run 0's generator, one run after the other."""

    def simulate(self, truth, streams):
        shared = streams["rangefinder"][0]
        return super().simulate(truth, {"rangefinder": [shared] * truth.position.shape[0]})


class FixedSeed(Rangefinder):
    """Noise from a generator of its own seed, whatever streams it is handed."""

    def simulate(self, truth, streams):
        runs = truth.position.shape[0]
        return super().simulate(truth, {"rangefinder": [np.random.default_rng(0) for _ in range(runs)]})


class OffGrid(Rangefinder):
    """A sample at every filter step while its settings say 20 Hz."""

    def simulate(self, truth, streams):
        record = super().simulate(truth, streams)
        height = truth.position[..., 2:3]
        return SensorRecord(np.where(np.isnan(record.values), height, record.values), np.ones_like(record.available))


class NoSettings(Rangefinder):
    Settings = None


@pytest.mark.slow
@pytest.mark.parametrize(
    ("cls", "message"),
    [
        pytest.param(WrongJacobian, "jacobian at step .* differs from central differences", id="WrongJacobian"),
        pytest.param(GlobalDraws, "global generator", id="GlobalDraws"),
        pytest.param(OneGenerator, "run 1 in a batch differs from run 1 alone", id="OneGenerator"),
        pytest.param(FixedSeed, "another seed gives the same samples", id="FixedSeed"),
        pytest.param(OffGrid, "off the grid of rate=20", id="OffGrid"),
        pytest.param(NoSettings, "Settings must be a dataclass", id="NoSettings"),
    ],
)
def test_a_broken_sensor_fails_on_its_bug(cls, message):
    with pytest.raises(AssertionError, match=message):
        check_sensor(cls)


def test_settings_its_own_checks_refuse_are_refused():
    from quadest.errors import ConfigError

    with pytest.raises(ConfigError, match="noise"):
        check_sensor(Rangefinder, settings=rangefinder.RangefinderSettings(noise=0.0))
