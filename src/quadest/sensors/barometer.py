"""Barometric altimeter on the shared truth: the altitude above the take-off point at the
sensor's own rate, with the error classes of the MIMU that have a barometric meaning.

    h̃_k = (1 + s) z_k + b0 + b(t_k) + n_k

- ``s`` (``scale_factor``, one-sigma fraction, per run): the error of the pressure-to-height
  scale (temperature and lapse-rate mismatch of the standard atmosphere);
- ``b0`` (``bias``, one-sigma m, per run): the reference error left after zeroing on the
  ground; ``b(t)``: its drift with the weather and the sensor's temperature, a random walk of
  density ``bias_random_walk`` (m/√s);
- ``n``: white noise of one-sigma ``white_noise`` (m) per sample, drawn under the sensor's
  :class:`~quadest.sensors.noise_laws.NoiseLaw`.

The MS5611 class (the PX4/ArduPilot default) resolves 0.012 mbar (≈ 0.1 m) at its highest
oversampling. Draw order from the run's ``"barometer"`` stream: ``s``, ``b0``, the walk's
increments (K+1), then the white noise (K+1). Samples every ``round(1/(rate T))`` filter steps;
NaN and unavailable in between.

:class:`Barometer` is the sensor (``model.aiding: [barometer, ...]``, settings
``sensor.barometer``), :class:`BarometerAiding` the filters' model of it, ``h = z``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from quadest.config.ranges import require_non_negative, require_positive
from quadest.sensors.base import Sensor, SensorModel, StateLayout, TrueMotion, sample_stride
from quadest.sensors.noise_laws import NoiseLaw, draw_noise
from quadest.sensors.record import SensorRecord


@dataclass
class BarometerSpec:
    """Barometer settings and error levels; also the config schema of ``sensor.barometer``."""

    rate: float = 50.0
    white_noise: float = 0.1
    bias: float = 0.0
    bias_random_walk: float = 0.005
    scale_factor: float = 0.0
    noise_law: NoiseLaw = field(default_factory=NoiseLaw)

    def variance(self, duration: float) -> float:
        """The variance a filter that does not estimate the bias assigns to a sample: white noise,
        turn-on bias and the random walk at mid-run (the convention of the MIMU's R,
        :func:`quadest.models.quadrotor_config.measurement_covariance`); the scale factor is left
        out (1 % of the 1 m flight altitude is 1 cm)."""
        return self.white_noise**2 + self.bias**2 + self.bias_random_walk**2 * duration / 2.0


def measure_barometer(
    spec: BarometerSpec, altitude: np.ndarray, sample_period: float, rngs: list[np.random.Generator]
) -> SensorRecord:
    """Altitude samples (B, K+1, 1) of the true altitudes (B, K+1); NaN between samples."""
    B, K1 = altitude.shape
    values = np.empty((B, K1, 1))
    for i, rng in enumerate(rngs):
        scale = spec.scale_factor * rng.standard_normal()
        bias = spec.bias * rng.standard_normal()
        increments = spec.bias_random_walk * np.sqrt(sample_period) * rng.standard_normal(K1)
        increments[0] = 0.0
        noise = draw_noise(spec.noise_law, rng, (K1,), spec.white_noise)
        values[i, :, 0] = (1.0 + scale) * altitude[i] + bias + np.cumsum(increments) + noise
    available = np.arange(K1) % sample_stride(spec.rate, sample_period, f"{Barometer.key()}.rate") == 0
    values[:, ~available] = np.nan
    return SensorRecord(values, available)


@dataclass
class BarometerAiding(SensorModel):
    """Altitude ``h = z``, the third component of the position: ``∂h/∂p = [0, 0, 1]``."""

    R: np.ndarray
    layout: StateLayout
    names: tuple[str, ...] = ("baro_z",)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.quantity("position", x, u)[..., 2:3].copy()

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = self._zeros(x)
        self.place(J, slice(0, 1), "position", np.array([[0.0, 0.0, 1.0]]), x, u)
        return J


class Barometer(Sensor):
    """The barometric altimeter (module docstring); ``R`` is :meth:`BarometerSpec.variance` (the
    filters do not estimate the bias) times the model's ``measurement_noise_inflation``."""

    config_name = "barometer"
    Settings = BarometerSpec
    streams = ("barometer",)
    measures = ("position",)

    @classmethod
    def validate(cls, settings: BarometerSpec, key: str, sample_period: float) -> None:
        super().validate(settings, key, sample_period)
        for name in ("bias", "bias_random_walk", "scale_factor"):
            require_non_negative(f"{key}.{name}", getattr(settings, name))
        require_positive(f"{key}.white_noise", settings.white_noise, "must be > 0 (R is built from it)")

    def simulate(self, truth: TrueMotion, streams: Mapping[str, list[np.random.Generator]]) -> SensorRecord:
        altitude = truth.position[..., 2]
        return measure_barometer(self.settings, altitude, self.context.sample_period, streams["barometer"])

    def measurement_model(self, layout: StateLayout) -> BarometerAiding:
        variance = self.settings.variance(self.context.duration)
        return BarometerAiding(self.context.noise_inflation * variance * np.eye(1), layout)
