"""Noise laws of the sensors (quadest.sensors.noise_laws): the Gaussian law is today's draw bit for
bit, and each other law has the fraction of outliers, the variances and the tails it documents.

Statistical bounds are 4.5 standard errors of the checked statistic (binomial for fractions,
χ² for variances, the fourth moment for a mixture's variance): a false alarm has probability
below 1e-5 per check, while every deliberate error tried (ε doubled, factor off, ν − 2 → ν, a burst
one sample short) moves the statistic by tens of standard errors.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from helpers import compose_config
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.sensors.mimu import TriadSpec, draw_triad_errors, measure_triad
from quadest.sensors.noise_laws import NoiseLaw, draw_noise, noise_multiplier

Z = 4.5  # standard errors allowed per statistical check


def _multiplier(law: NoiseLaw, shape, seed: int = 7) -> np.ndarray:
    """The multiplier ``s`` that ``draw_noise(law, default_rng(seed), shape, σ)`` applies."""
    rng = np.random.default_rng(seed)
    rng.standard_normal(shape)
    return np.broadcast_to(noise_multiplier(law, rng, shape), shape)


def test_gaussian_mimu_draws_are_the_plain_generator_draws_bit_for_bit():
    """measure_triad with the default and the explicit Gaussian law against the draws written out
    here with the same generators (random-walk increments first, then the white noise)."""
    spec = TriadSpec(0.01, 0.003, 5e-3, 0.2, 3e-3, 4e-3)
    T, K1 = 0.01, 301
    errors = draw_triad_errors(spec, [np.random.default_rng(s) for s in range(3)])
    y = np.random.default_rng(9).standard_normal((3, K1, 3))
    walk, white = np.empty((3, K1, 3)), np.empty((3, K1, 3))
    for i in range(3):
        rng = np.random.default_rng(100 + i)
        inc = spec.bias_random_walk * np.sqrt(T) * rng.standard_normal((K1, 3))
        inc[0] = 0.0
        walk[i] = np.cumsum(inc, axis=0)
        white[i] = spec.white_noise / np.sqrt(T) * rng.standard_normal((K1, 3))
    expected = errors.apply(y) + walk + white
    for law in (None, NoiseLaw("gaussian"), NoiseLaw("contaminated", epsilon=0.0, variance_factor=100.0)):
        got = measure_triad(spec, errors, y, T, [np.random.default_rng(100 + i) for i in range(3)], law)
        assert np.array_equal(got, expected)


def test_contaminated_draws_have_the_outlier_fraction_and_variances_of_the_law():
    N, sigma = 400_000, 0.3
    for eps, factor in ((0.1, 5.0), (0.05, 100.0)):
        law = NoiseLaw("contaminated", epsilon=eps, variance_factor=factor)
        s = _multiplier(law, (N,))
        x = draw_noise(law, np.random.default_rng(7), (N,), sigma)
        outlier = s == np.sqrt(factor)
        assert np.all(outlier | (s == 1.0))
        assert abs(outlier.mean() - eps) < Z * np.sqrt(eps * (1 - eps) / N)
        for mask, var in ((outlier, factor * sigma**2), (~outlier, sigma**2)):
            k = mask.sum()
            assert abs(np.mean(x[mask] ** 2) / var - 1.0) < Z * np.sqrt(2.0 / k)  # χ²(k)/k
        total = sigma**2 * (1 - eps + eps * factor)
        fourth = 3 * sigma**4 * (1 - eps + eps * factor**2)
        assert abs(np.mean(x**2) - total) < Z * np.sqrt((fourth - total**2) / N)


def test_student_t_draws_have_the_nominal_variance_and_the_t_shape():
    N, sigma, dof = 400_000, 2.0, 6.0
    x = draw_noise(NoiseLaw("student_t", dof=dof), np.random.default_rng(3), (N,), sigma)
    fourth = 3 * sigma**4 * (dof - 2) / (dof - 4)  # E x⁴ of a t scaled to variance σ²
    assert abs(np.mean(x**2) - sigma**2) < Z * np.sqrt((fourth - sigma**4) / N)
    t = x / (sigma * np.sqrt((dof - 2) / dof))
    assert stats.kstest(t, stats.t(dof).cdf).pvalue > 1e-4


def test_bursts_start_at_the_rate_last_the_length_and_hit_every_axis():
    N, rate, length, factor = 200_000, 0.01, 10, 25.0
    law = NoiseLaw("bursts", rate=rate, length=length, variance_factor=factor)
    s = _multiplier(law, (N, 3))
    assert np.all(s == s[:, :1])  # a burst covers the whole sample
    inside = s[:, 0] == np.sqrt(factor)
    assert np.all(inside | (s[:, 0] == 1.0))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(int), [0]])))
    runs = edges[1::2] - edges[::2]
    assert runs[:-1].min() == length  # an isolated burst is exactly `length` samples (the last may be cut)
    # a burst region begins at k when a burst starts there and none started in the `length` before
    expected_runs = N * rate * (1 - rate) ** length
    assert abs(runs.size - expected_runs) < Z * np.sqrt(expected_runs)
    q = 1 - (1 - rate) ** length  # P(inside a burst)
    assert abs(inside.mean() - q) < Z * np.sqrt(q * (1 - q) * (2 * length - 1) / N)  # correlated over `length`


@pytest.mark.parametrize(
    ("kind", "setting", "value"),
    [
        ("cauchy", "kind", "cauchy"),
        ("contaminated", "epsilon", 1.5),
        ("contaminated", "variance_factor", 0),
        ("student_t", "dof", 2),
        ("bursts", "rate", 2),
        ("bursts", "length", 0),
    ],
)
def test_a_bad_noise_law_is_one_config_error_naming_its_key(kind, setting, value):
    key = "sensor.gyro.noise_law"
    with pytest.raises(ConfigError) as err:
        validate(compose_config([f"{key}.kind={kind}", f"{key}.{setting}={value}"]))
    assert err.value.key == f"{key}.{setting}" and "\n" not in str(err.value)


def test_the_other_laws_settings_are_not_checked():
    validate(compose_config(["sensor.accel.noise_law.kind=gaussian", "sensor.accel.noise_law.dof=1"]))
