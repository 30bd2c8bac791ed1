"""A sensor rate that does not divide the filter rate is refused with one line naming the sensor's
own key (``sensor.gps.rate``, ``model.magnetometer.rate``, …) and the rates it may have: by the
checks before any work (:meth:`~quadest.sensors.base.Sensor.validate`) and by the sampling itself
(a sensor's data made without those checks), never with another sensor's key."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from quadest.errors import ConfigError
from quadest.sensors.base import SensorContext, TrueMotion, allowed_rates
from quadest.sensors.registry import is_builtin, sensor_classes

T = 0.01  # a 100 Hz filter
RATED = sorted(
    name
    for name, cls in sensor_classes().items()
    if is_builtin(cls) and "rate" in {f.name for f in dataclasses.fields(cls.Settings)}
)


def _with_rate(name: str, rate: float):
    cls = sensor_classes()[name]
    return cls, dataclasses.replace(cls.Settings(), rate=rate)


def test_every_builtin_aiding_sensor_has_a_rate():
    assert {"barometer", "gps", "magnetometer", "vision"} <= set(RATED)


def test_the_allowed_rates_are_the_divisors_of_the_filter_rate():
    """100 Hz / k for k = 1 … 5, each of which the check accepts, and the rule for the rest."""
    message = allowed_rates(T)
    assert message.startswith("one of 100, 50, 33.3333, 25, 20, … Hz") and "100/k" in message
    cls, settings = _with_rate("gps", 100.0)
    for k in range(1, 6):
        cls.validate(dataclasses.replace(settings, rate=100.0 / k), cls.key(), T)


@pytest.mark.parametrize("name", RATED)
@pytest.mark.parametrize("rate", [30.0, 200.0])
def test_a_bad_rate_is_refused_naming_the_sensors_own_key_and_the_allowed_rates(name, rate):
    """30 Hz does not divide 100 Hz; 200 Hz exceeds it."""
    cls, settings = _with_rate(name, rate)
    with pytest.raises(ConfigError) as caught:
        cls.validate(settings, cls.key(), T)
    line = str(caught.value)
    assert "\n" not in line
    assert line.startswith(f"{cls.key()}.rate={rate}") and allowed_rates(T) in line


@pytest.mark.parametrize("name", RATED)
def test_the_sampling_itself_names_the_sensors_own_key(name):
    """Data made without the checks (a sensor built and sampled directly) fails on the same line:
    the sensor's key, not another's."""
    cls, settings = _with_rate(name, 30.0)
    K1 = 5
    motion = TrueMotion(
        np.arange(K1) * T,
        np.tile([0.0, 0.0, 1.0], (1, K1, 1)),
        np.zeros((1, K1, 3)),
        np.tile([1.0, 0.0, 0.0, 0.0], (1, K1, 1)),
    )
    sensor = cls(settings, SensorContext(sample_period=T, duration=(K1 - 1) * T))
    streams = {stream: [np.random.default_rng(0)] for stream in cls.stream_names()}
    with pytest.raises(ConfigError) as caught:
        sensor.simulate(motion, streams)
    assert str(caught.value).startswith(f"{cls.key()}.rate=30.0") and allowed_rates(T) in str(caught.value)
