"""Sensor behaviours a single-point bug breaks without any other test noticing.

- A sensor's ``R`` adds variances: the GPS's ``R`` (white noise plus the drift's stationary
  variance on the position, as the filters do not estimate the drift) equals the variance of the
  errors :func:`~quadest.sensors.gps.measure_gps` draws, for a receiver with non-zero drift and
  standard deviations away from 1 (where adding standard deviations, or forgetting the drift,
  changes ``R`` by 30 % or more); and the barometer's ``R`` (white noise, turn-on bias and the
  random walk at mid-run) equals the variance of its drawn errors at mid-run. Monte Carlo over B
  runs at one sample: the sample variance over runs is σ² χ²(B−1)/(B−1), so the bound is
  4.5 √(2/(B−1)) relative.
- The camera's field of view reads ``image_size`` as [width, height]: on a non-square image, a
  line of sight just inside the half-width along x is seen and one just outside the half-height
  along y is not; a beacon on the optical axis is seen at (width/2, height/2).
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_settings
from quadest.sensors.barometer import measure_barometer
from quadest.sensors.gps import measure_gps
from quadest.sensors.vision import VisionSpec, in_view, measure_vision
from quadest.simulation.registry import build_data

Z = 4.5


@pytest.mark.slow
def test_the_gps_r_adds_the_drifts_variance_to_the_white_noises():
    settings = compose_settings(["model=ins", "model.aiding=[gps]", "runs=2", "duration=1.0", "progress=false",
                                 "sensor.gps.position_drift=0.7", "sensor.gps.horizontal_noise=0.4",
                                 "sensor.gps.vertical_noise=1.5", "sensor.gps.velocity_noise=0.3"])  # fmt: skip
    data = build_data(settings)
    spec = settings.sensor.gps
    R = data.model.aiding["gps"].R / settings.model.measurement_noise_inflation
    assert np.count_nonzero(R - np.diag(np.diag(R))) == 0
    B = 8000
    rngs = [np.random.default_rng([17, i]) for i in range(B)]
    truth = np.zeros((B, 1, 3))
    errors = measure_gps(spec, truth, truth, 0.01, rngs).values[:, 0, :]
    variance = errors.var(axis=0, ddof=1)
    np.testing.assert_array_less(np.abs(variance / np.diag(R) - 1.0), Z * np.sqrt(2.0 / (B - 1)))


def test_the_cameras_field_of_view_is_width_by_height():
    spec = VisionSpec(image_size=[640.0, 200.0], focal_length=200.0, max_range=100.0)
    half_width, half_height = 320.0 / 200.0, 100.0 / 200.0  # tangent of the half angles
    z = 5.0
    sights = np.array(
        [
            [0.98 * half_width * z, 0.0, z],  # just inside the width
            [1.02 * half_width * z, 0.0, z],  # just outside the width
            [0.0, 0.98 * half_height * z, z],  # just inside the height
            [0.0, 1.02 * half_height * z, z],  # just outside the height
            [0.0, -1.02 * half_height * z, z],
        ]
    )
    np.testing.assert_array_equal(in_view(sights[None], spec)[0], [True, False, True, False, False])
    # a beacon on the optical axis (the forward mount looks along body x) is seen at the centre
    centred = VisionSpec(image_size=[640.0, 200.0], pixel_noise=0.0, beacons=[[5.0, 0.0, 0.0]], rate=100.0)
    q, p = np.tile([1.0, 0.0, 0.0, 0.0], (1, 2, 1)), np.zeros((1, 2, 3))
    record = measure_vision(centred, q, p, 0.01, [np.random.default_rng(0)])
    np.testing.assert_allclose(record.values[0, 0], [320.0, 100.0], atol=1e-9)


def test_the_barometer_r_adds_the_variances_of_its_noise_bias_and_drift_at_mid_run():
    """A barometer with a turn-on bias, white noise and a random walk (none of them 1): ``R`` is
    the variance of the drawn errors at mid-run (the convention of ``BarometerSpec.variance``),
    against the sample variance over B runs within the χ² bound."""
    overrides = [
        "sensor.barometer.bias=0.3",
        "sensor.barometer.white_noise=0.2",
        "sensor.barometer.bias_random_walk=0.1",
    ]
    settings = compose_settings(["model=ins", "model.aiding=[barometer]", "runs=2", "duration=2.0", "progress=false",
                                 *overrides])  # fmt: skip
    data = build_data(settings)
    R = float(data.model.aiding["barometer"].R[0, 0]) / settings.model.measurement_noise_inflation
    T, duration = float(settings.sample_period), float(data.time[-1] - data.time[0])
    B, K1 = 8000, data.time.size
    record = measure_barometer(
        settings.sensor.barometer, np.zeros((B, K1)), T, [np.random.default_rng([18, i]) for i in range(B)]
    )
    mid = int(np.flatnonzero(record.available & (np.arange(K1) * T >= duration / 2.0 - 1e-9))[0])
    assert mid * T == pytest.approx(duration / 2.0)
    variance = record.values[:, mid, 0].var(ddof=1)
    assert abs(variance / R - 1.0) <= Z * np.sqrt(2.0 / (B - 1)), (variance, R)
