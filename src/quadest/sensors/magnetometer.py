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
"""

from __future__ import annotations

import numpy as np

from quadest.errors import ConfigError
from quadest.numerics import quaternion as quat
from quadest.sensors.mimu import TriadErrors, TriadSpec, measure_triad
from quadest.sensors.record import SensorRecord


def field_in_body(q: np.ndarray, mag_earth: np.ndarray) -> np.ndarray:
    """``R(q)ᵀ m_e`` (..., 3): the earth field in the body frame of attitudes ``q`` (..., 4)."""
    return quat.rotate(quat.conjugate(q), np.broadcast_to(mag_earth, (*q.shape[:-1], 3)))


def sample_stride(rate: float, sample_period: float) -> int:
    """Filter steps between two samples of a sensor at ``rate`` Hz; the rate must divide the
    filter rate ``1/sample_period`` and not exceed it."""
    ratio = 1.0 / (rate * sample_period)
    stride = round(ratio)
    if stride < 1 or abs(ratio - stride) > 1e-9 * ratio:
        raise ConfigError(
            "model.magnetometer.rate", rate, f"must divide the filter rate 1/sample_period = {1.0 / sample_period:g} Hz"
        )
    return stride


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
    stride = sample_stride(rate, sample_period)
    available = np.arange(K1) % stride == 0
    truth = field_in_body(q_true[:, available], mag_earth)
    values = np.full((B, K1, 3), np.nan)
    values[:, available] = measure_triad(spec, errors, truth, stride * sample_period, rngs)
    return SensorRecord(values, available)
