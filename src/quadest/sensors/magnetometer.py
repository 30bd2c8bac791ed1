"""Three-axis magnetometer on the shared truth: the earth field seen from the body, with the
MIMU's error classes (:mod:`quadest.sensors.mimu`) read as their magnetic meanings, at its own rate.

For the true attitude ``q`` (body → earth) and the earth-frame field ``m_e``:

    m̃ = (I + S + S± ⊙ sgn(m) + M) m + b0 + b(t) + n,    m = R(q)ᵀ m_e

- ``S`` (``scale_factor``) and ``M`` (``cross_coupling``): the **soft-iron** distortion
  (a symmetric soft-iron matrix is one such ``I + S + M``; Gebre-Egziabher et al. 2006, "Calibration
  of strapdown magnetometers in magnetic field domain", J. Aerosp. Eng. 19(2), eq. 3);
- ``b0`` (``bias``): the **hard-iron** offset; ``b(t)``: its slow drift (``bias_random_walk``);
- ``n``: white noise of density ``white_noise`` (σ_d = σ_c/√T_mag at the magnetometer's period);
- ``asymmetry`` exists for symmetry with the MIMU and is zero in the shipped config.

The errors are drawn once per run from the ``"mag_errors"`` stream and the noise from
``"mag_noise"`` (:mod:`quadest.montecarlo.streams`), so adding the magnetometer changes no other
draw. Samples exist every ``round(1/(rate·T))`` filter steps (``rate`` must divide the filter
rate); the others are NaN and marked unavailable in the :class:`SensorRecord`. Units are those of
``m_e`` (µT in the shipped configs).

:class:`Magnetometer` is the sensor (``model.aiding: [magnetometer, ...]`` of ``model=ins``, and
the built-in second sensor of ``model=attitude``; settings ``model.magnetometer``,
:class:`MagnetometerConf`), :class:`MagnetometerAiding` the filters' model of it on the INS:
``h = M(R(q)ᵀ m_e)`` with each run's known soft/hard-iron errors when ``calibrated`` (nominal,
error-free ones otherwise).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from quadest.config.ranges import require_non_negative, require_positive
from quadest.errors import ConfigError
from quadest.numerics import quaternion as quat
from quadest.sensors.base import Sensor, SensorModel, StateLayout, TrueMotion, check_rate, sample_stride
from quadest.sensors.mimu import TriadErrors, TriadSpec, draw_triad_errors, measure_triad
from quadest.sensors.record import SensorRecord


@dataclass
class MagnetometerConf(TriadSpec):
    """A magnetometer (this module): its rate (Hz, dividing the filter rate), the earth-frame field
    (µT; default: north 20, down 45 in the z-up frame, inclination 66°) and the MIMU's error classes
    read as soft iron (``scale_factor``, ``cross_coupling``), hard iron (``bias``) and its drift,
    and white noise (µT/√Hz); the config schema of ``model.magnetometer``."""

    rate: float = 50.0
    earth_field: list[float] = field(default_factory=lambda: [20.0, 0.0, -45.0])
    scale_factor: float = 0.02
    cross_coupling: float = 0.01
    bias: float = 5.0
    white_noise: float = 0.03


def field_in_body(q: np.ndarray, mag_earth: np.ndarray) -> np.ndarray:
    """``R(q)ᵀ m_e`` (..., 3): the earth field in the body frame of attitudes ``q`` (..., 4)."""
    return quat.rotate(quat.conjugate(q), np.broadcast_to(mag_earth, (*q.shape[:-1], 3)))


def measure_magnetometer(
    spec: TriadSpec,
    errors: TriadErrors,
    q_true: np.ndarray,
    mag_earth: np.ndarray,
    sample_period: float,
    rate: float,
    rngs: list[np.random.Generator],
) -> SensorRecord:
    """Magnetometer samples (B, K+1, 3), NaN between samples, and their availability (K+1,)."""
    B, K1, _ = q_true.shape
    stride = sample_stride(rate, sample_period, f"{Magnetometer.key()}.rate")
    available = np.arange(K1) % stride == 0
    truth = field_in_body(q_true[:, available], mag_earth)
    values = np.full((B, K1, 3), np.nan)
    values[:, available] = measure_triad(spec, errors, truth, stride * sample_period, rngs)
    return SensorRecord(values, available)


@dataclass
class MagnetometerAiding(SensorModel):
    """The earth field through the magnetometer's known soft/hard-iron errors (per run):
    ``h = M(R(q)ᵀ m_e)``, ``∂h/∂δθ = M' [m_b]×`` (as :mod:`quadest.models.attitude`)."""

    mag_earth: np.ndarray
    errors: TriadErrors
    R: np.ndarray
    layout: StateLayout
    names: tuple[str, ...] = ("mag_x", "mag_y", "mag_z")

    def select(self, runs: slice | np.ndarray) -> MagnetometerAiding:
        return replace(self, errors=self.errors[runs])

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.errors.apply(field_in_body(self.quantity("attitude", x, u), self.mag_earth))

    def jacobian(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        m_b = field_in_body(self.quantity("attitude", x, u), self.mag_earth)
        J = self._zeros(x)
        self.place(J, slice(None), "attitude", self.errors.jacobian(m_b) @ quat.skew(m_b), x, u)
        return J


class Magnetometer(Sensor):
    """The magnetometer (module docstring), its settings at ``model.magnetometer``, its error levels
    scaled by ``sensor.error_scale`` like the MIMU's. ``R`` is the white noise's variance at the
    magnetometer's period plus the hard-iron drift's variance at mid-run (the filters do not
    estimate it), times the model's ``measurement_noise_inflation``."""

    config_name = "magnetometer"
    Settings = MagnetometerConf
    settings_key = "model.magnetometer"
    streams = ("mag_errors", "mag_noise")
    measures = ("attitude",)

    @classmethod
    def validate(cls, settings: MagnetometerConf, key: str, sample_period: float) -> None:
        check_rate(f"{key}.rate", settings.rate, sample_period)
        if len(settings.earth_field) != 3 or not any(settings.earth_field):
            raise ConfigError(f"{key}.earth_field", list(settings.earth_field), "3 values, not all 0")
        for name in TriadSpec.__dataclass_fields__:
            require_non_negative(f"{key}.{name}", getattr(settings, name))
        require_positive(f"{key}.white_noise", settings.white_noise, "must be > 0 (R from it)")

    def simulate(self, truth: TrueMotion, streams: Mapping[str, list[np.random.Generator]]) -> SensorRecord:
        s, T = self.settings, self.context.sample_period
        self.triad = TriadSpec(**{k: float(getattr(s, k)) for k in TriadSpec.__dataclass_fields__}).scaled(
            self.context.error_scale
        )
        self.errors = draw_triad_errors(self.triad, streams["mag_errors"])
        self.mag_earth = np.array(s.earth_field, dtype=float)
        rate = float(s.rate)
        return measure_magnetometer(
            self.triad, self.errors, truth.attitude, self.mag_earth, T, rate, streams["mag_noise"]
        )

    def noise_covariance(self) -> np.ndarray:
        """``R`` (3, 3) of the filters (class docstring)."""
        mag, T, duration = self.triad, self.context.sample_period, self.context.duration
        stride = sample_stride(float(self.settings.rate), T, f"{self.key()}.rate")
        r = mag.white_noise_std(stride * T) ** 2 + mag.bias_random_walk**2 * duration / 2.0
        return self.context.noise_inflation * r * np.eye(3)

    def assumed_errors(self) -> TriadErrors:
        """The soft/hard-iron errors the filters use: each run's drawn ones when ``calibrated``,
        nominal (error-free) ones otherwise."""
        return self.errors if self.context.calibrated else TriadErrors.nominal(self.errors.bias.shape[0])

    def measurement_model(self, layout: StateLayout) -> MagnetometerAiding:
        return MagnetometerAiding(self.mag_earth, self.assumed_errors(), self.noise_covariance(), layout)
