"""``model.aiding: [..., rangefinder]``: a downward rangefinder, the height above flat ground at
z = 0 (docs/sensors.md walks through this file; the tests register it as an out-of-tree plugin).

    z̃_k = z_k + n_k,    h(x) = z,    ∂h/∂p = [0, 0, 1]

with ``n`` white noise of one-sigma ``noise`` drawn under its noise law, a sample every
``1/rate`` s, and none while the vehicle is above ``max_range`` in some run (one availability
mask per batch). The vehicle's tilt is neglected (a level beam).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from quadest.config.ranges import require_positive
from quadest.sensors.base import Sensor, SensorModel, StateLayout, TrueMotion, available_samples
from quadest.sensors.noise_laws import NoiseLaw, draw_noise
from quadest.sensors.record import SensorRecord


@dataclass
class RangefinderSettings:
    """The settings node ``sensor.rangefinder``: its schema."""

    rate: float = 20.0  # Hz, must divide the filter rate 1/sample_period
    noise: float = 0.02  # m, one-sigma white noise per sample
    max_range: float = 4.0  # m, no sample above it
    noise_law: NoiseLaw = field(default_factory=NoiseLaw)


@dataclass
class RangefinderAiding(SensorModel):
    """What the filters predict: ``h = z`` with its Jacobian on the model's position."""

    R: np.ndarray
    layout: StateLayout
    names: tuple[str, ...] = ("range",)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.quantity("position", x, u)[..., 2:3].copy()

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = self._zeros(x)
        self.place(J, slice(0, 1), "position", np.array([[0.0, 0.0, 1.0]]), x, u)
        return J


class Rangefinder(Sensor):
    """The sensor, registered once: its name, settings, checks, samples and filters' model."""

    config_name = "rangefinder"
    Settings = RangefinderSettings
    measures = ("position",)

    @classmethod
    def validate(cls, settings: RangefinderSettings, key: str, sample_period: float) -> None:
        super().validate(settings, key, sample_period)  # rate and noise_law
        require_positive(f"{key}.noise", settings.noise, "must be > 0 (R is built from it)")
        require_positive(f"{key}.max_range", settings.max_range)

    def simulate(self, truth: TrueMotion, streams: Mapping[str, list[np.random.Generator]]) -> SensorRecord:
        s, height = self.settings, truth.position[..., 2]  # (B, K+1)
        values = np.empty((*height.shape, 1))
        for i, rng in enumerate(streams["rangefinder"]):  # one generator per run, its own stream
            values[i, :, 0] = height[i] + draw_noise(s.noise_law, rng, height.shape[1:], s.noise)
        available = available_samples(s.rate, self.context.sample_period, height.shape[1], f"{self.key()}.rate")
        available &= (height <= s.max_range).all(axis=0)
        values[:, ~available] = np.nan
        return SensorRecord(values, available)

    def measurement_model(self, layout: StateLayout) -> RangefinderAiding:
        return RangefinderAiding(self.context.noise_inflation * self.settings.noise**2 * np.eye(1), layout)
