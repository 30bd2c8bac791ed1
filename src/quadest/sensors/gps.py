"""GPS receiver on the shared truth: earth-frame position and (optionally) velocity at the
receiver's own rate, with an optional latency.

Measured at filter step ``k`` (a fix every ``round(1/(rate T))`` steps; the rate must divide the
filter rate):

    p̃_k = p(t_k − τ) + d_k + n_p,    ṽ_k = v(t_k − τ) + n_v

- ``n_p``: white noise, one-sigma ``horizontal_noise`` (x, y) and ``vertical_noise`` (z);
  ``n_v``: white noise of one-sigma ``velocity_noise`` per axis; both drawn under the receiver's
  :class:`~quadest.sensors.noise_laws.NoiseLaw`;
- ``d_k``: the slowly varying position error of a real receiver (satellite geometry, ionosphere,
  multipath), a first-order Gauss–Markov process per axis with stationary one-sigma
  ``position_drift`` and correlation time ``drift_time``, started from its stationary law
  (Gelb 1974, table 3.1-1; Farrell 2008, §4.9 for GPS error models);
- ``τ``: ``latency`` rounded to whole filter steps (the fix describes the vehicle one latency
  ago). The filters' ``h`` compensates it to first order, ``p(t − τ) ≈ p − τ v`` (see
  :func:`gps_prediction`).

Draw order from the run's ``"gps"`` stream: the drift's normals (K+1, 3), then the white noise
(K+1, 6), so the noise law does not move the drift draws. Units: m and m/s.

:class:`Gps` is the sensor (``model.aiding: [gps, ...]``, settings ``sensor.gps``), and
:class:`GpsAiding` the filters' model of it: ``h = [p − τ v, v]`` with its Jacobian on the
model's position and velocity (docs/ins.md).
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
class GPSSpec:
    """Receiver settings and error levels; also the config schema of ``sensor.gps``."""

    rate: float = 5.0
    latency: float = 0.0
    measure_velocity: bool = True
    horizontal_noise: float = 1.0
    vertical_noise: float = 1.5
    velocity_noise: float = 0.05
    position_drift: float = 0.0
    drift_time: float = 60.0
    noise_law: NoiseLaw = field(default_factory=NoiseLaw)

    @property
    def m(self) -> int:
        return 6 if self.measure_velocity else 3

    def white_std(self) -> np.ndarray:
        """One-sigma white noise of the ``m`` components."""
        s = [self.horizontal_noise, self.horizontal_noise, self.vertical_noise] + [self.velocity_noise] * 3
        return np.array(s[: self.m])

    def measurement_names(self) -> tuple[str, ...]:
        return ("gps_x", "gps_y", "gps_z", "gps_vx", "gps_vy", "gps_vz")[: self.m]

    def latency_steps(self, sample_period: float) -> int:
        return round(self.latency / sample_period)


def gps_prediction(p: np.ndarray, v: np.ndarray, delay: float, measure_velocity: bool) -> np.ndarray:
    """What the receiver reports for positions ``p`` and velocities ``v`` (..., 3) with a latency of
    ``delay`` s, to first order: ``[p − delay·v, v]`` (or the position only)."""
    position = p - delay * v
    return np.concatenate([position, v], axis=-1) if measure_velocity else position


def gauss_markov(normals: np.ndarray, sigma: float, time_constant: float, step: float) -> np.ndarray:
    """First-order Gauss–Markov sequence from standard normals (K+1, d): ``d_0 = σ w_0``,
    ``d_k = φ d_{k−1} + σ √(1 − φ²) w_k`` with ``φ = exp(−step/time_constant)`` (stationary)."""
    phi = np.exp(-step / time_constant)
    out = np.empty_like(normals)
    out[0] = sigma * normals[0]
    drive = sigma * np.sqrt(1.0 - phi**2) * normals
    for k in range(1, normals.shape[0]):
        out[k] = phi * out[k - 1] + drive[k]
    return out


def measure_gps(
    spec: GPSSpec, p_true: np.ndarray, v_true: np.ndarray, sample_period: float, rngs: list[np.random.Generator]
) -> SensorRecord:
    """GPS fixes (B, K+1, m) of the true positions and velocities (B, K+1, 3); NaN between fixes."""
    B, K1, _ = p_true.shape
    delay = spec.latency_steps(sample_period)
    source = np.maximum(np.arange(K1) - delay, 0)
    values = np.empty((B, K1, spec.m))
    for i, rng in enumerate(rngs):
        drift = gauss_markov(rng.standard_normal((K1, 3)), spec.position_drift, spec.drift_time, sample_period)
        white = draw_noise(spec.noise_law, rng, (K1, 6), 1.0)[:, : spec.m] * spec.white_std()
        ideal = gps_prediction(p_true[i, source], v_true[i, source], 0.0, spec.measure_velocity)
        values[i] = ideal + white
        values[i, :, :3] += drift
    available = np.arange(K1) % sample_stride(spec.rate, sample_period, f"{Gps.key()}.rate") == 0
    values[:, ~available] = np.nan
    return SensorRecord(values, available)


@dataclass
class GpsAiding(SensorModel):
    """Position (and velocity) with the receiver's latency ``delay`` compensated to first order:
    ``h = [p − delay·v, v]`` (:func:`gps_prediction`), so ``∂h/∂p = [I; 0]`` and
    ``∂h/∂v = [−delay·I; I]``."""

    spec: GPSSpec
    delay: float
    R: np.ndarray
    layout: StateLayout

    @property
    def names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.spec.measurement_names()

    @property
    def groups(self) -> dict[str, tuple[str, ...]]:
        """Position and velocity apart (their errors differ in kind: drift against white noise)."""
        return {"position": self.names[:3], "velocity": self.names[3:]} if self.spec.measure_velocity else {}

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        p, v = self.quantity("position", x, u), self.quantity("velocity", x, u)
        return gps_prediction(p, v, self.delay, self.spec.measure_velocity)

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        J = self._zeros(x)
        self.place(J, slice(0, 3), "position", np.eye(3), x, u)
        self.place(J, slice(0, 3), "velocity", -self.delay * np.eye(3), x, u)
        if self.spec.measure_velocity:
            self.place(J, slice(3, 6), "velocity", np.eye(3), x, u)
        return J


class Gps(Sensor):
    """The GPS receiver (module docstring). ``R`` is the white noise's variance plus the drift's
    stationary variance on the position (the filters do not estimate the drift), times the
    model's ``measurement_noise_inflation``."""

    config_name = "gps"
    Settings = GPSSpec
    streams = ("gps",)
    measures = ("position", "velocity")

    @classmethod
    def validate(cls, settings: GPSSpec, key: str, sample_period: float) -> None:
        super().validate(settings, key, sample_period)
        for name in ("latency", "position_drift"):
            require_non_negative(f"{key}.{name}", getattr(settings, name))
        for name in ("horizontal_noise", "vertical_noise", "velocity_noise", "drift_time"):
            require_positive(f"{key}.{name}", getattr(settings, name), "must be > 0 (R is built from it)")

    def simulate(self, truth: TrueMotion, streams: Mapping[str, list[np.random.Generator]]) -> SensorRecord:
        return measure_gps(self.settings, truth.position, truth.velocity, self.context.sample_period, streams["gps"])

    def measurement_model(self, layout: StateLayout) -> GpsAiding:
        spec, T = self.settings, self.context.sample_period
        R = np.diag(spec.white_std() ** 2)
        R[0:3, 0:3] += spec.position_drift**2 * np.eye(3)
        return GpsAiding(spec, spec.latency_steps(T) * T, self.context.noise_inflation * R, layout)
