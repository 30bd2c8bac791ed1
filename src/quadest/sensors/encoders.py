"""Rotor encoders: the rotor speeds the filters receive as their input ``u`` (thesis §5.1)."""

from __future__ import annotations

import numpy as np


def encoder_resolution(lines: int, sample_period: float) -> float:
    """Speed quantum of an incremental encoder counted over one sample, ``2π / (lines T)``."""
    return 2.0 * np.pi / (lines * sample_period)


def measure_rotor_speeds(
    speeds: np.ndarray,
    lines: int,
    noise_std: float,
    sample_period: float,
    rngs: list[np.random.Generator],
) -> np.ndarray:
    """Encoder readings (B, K+1, 4): white noise of ``noise_std`` rad/s, then quantisation to the
    encoder resolution when ``lines > 0`` (256 lines at T = 0.01 s give about 2.5 rad/s steps)."""
    out = np.array(speeds, dtype=float, copy=True)
    if noise_std > 0.0:
        for i, rng in enumerate(rngs):
            out[i] += noise_std * rng.standard_normal(out[i].shape)
    if lines > 0:
        q = encoder_resolution(lines, sample_period)
        out = np.round(out / q) * q
    return out
