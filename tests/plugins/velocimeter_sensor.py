"""``model.aiding: [velocimeter]``: a velocity sensor (optical flow over a known height, a Doppler
radar), the earth-frame velocity with white noise, ``h(x) = v``, ``∂h/∂v = I``. Every model that
estimates the velocity offers it, ``model=quadrotor`` included (docs/sensors.md)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from quadest.config.ranges import require_positive
from quadest.sensors.base import Sensor, SensorModel, StateLayout, TrueMotion, available_samples
from quadest.sensors.record import SensorRecord


@dataclass
class VelocimeterSettings:
    rate: float = 10.0  # Hz
    noise: float = 0.05  # m/s, one-sigma per axis and sample


@dataclass
class VelocimeterAiding(SensorModel):
    R: np.ndarray
    layout: StateLayout
    names: tuple[str, ...] = ("flow_vx", "flow_vy", "flow_vz")

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.quantity("velocity", x, u).copy()

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = self._zeros(x)
        self.place(J, slice(0, 3), "velocity", np.eye(3), x, u)
        return J


class Velocimeter(Sensor):
    """The velocity sensor (module docstring)."""

    config_name = "velocimeter"
    Settings = VelocimeterSettings
    measures = ("velocity",)

    @classmethod
    def validate(cls, settings: VelocimeterSettings, key: str, sample_period: float) -> None:
        super().validate(settings, key, sample_period)
        require_positive(f"{key}.noise", settings.noise, "must be > 0 (R is built from it)")

    def simulate(self, truth: TrueMotion, streams: Mapping[str, list[np.random.Generator]]) -> SensorRecord:
        v, s = truth.velocity, self.settings
        values = v + s.noise * np.stack([rng.standard_normal(v.shape[1:]) for rng in streams["velocimeter"]])
        available = available_samples(s.rate, self.context.sample_period, v.shape[1], f"{self.key()}.rate")
        values[:, ~available] = np.nan
        return SensorRecord(values, available)

    def measurement_model(self, layout: StateLayout) -> VelocimeterAiding:
        return VelocimeterAiding(self.context.noise_inflation * self.settings.noise**2 * np.eye(3), layout)
