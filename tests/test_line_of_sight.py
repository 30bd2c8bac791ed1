"""The camera's unit line-of-sight measurement (``sensor.vision.kind: line_of_sight``, seed 004
§1.3.2, :mod:`quadest.sensors.vision`): unit norm, the projection's and the error-state
Jacobians against finite differences, the draws' noise law (Gaussian and seed 004's contaminated
eq. 63), the availability it shares with the pixel camera, its config checks, and the filters
on it (χ² consistency on the figure eight)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2, norm

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.estimators.registry import build_estimator
from quadest.models.ins import InsFilterModel, ins_layout
from quadest.numerics import quaternion as quat
from quadest.runner import run_estimator
from quadest.sensors.noise_laws import NoiseLaw
from quadest.sensors.vision import (
    VisionAiding,
    VisionSpec,
    line_of_sight,
    measure_vision,
    mount_rotation,
    project,
    projection_jacobian,
)
from quadest.simulation.registry import build_data

T = 0.01
EPS = np.finfo(float).eps


def _rngs(seed: int, runs: int) -> list[np.random.Generator]:
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(runs)]


def _variance_ok(samples: np.ndarray, sigma2: float, z: float = 4.5) -> bool:
    """``|s² − σ²| < z σ² √(2/(N−1))`` (normal sample variance's standard error, z = 4.5: a false
    alarm about once in 10⁵)."""
    return abs(samples.var(ddof=1) - sigma2) < z * sigma2 * np.sqrt(2.0 / (samples.size - 1))


def _state(rng: np.random.Generator, B: int) -> np.ndarray:
    """Random INS states 8–20 m behind the default beacons (10 m ahead), attitudes within ±0.3 rad."""
    return np.concatenate(
        [quat.from_euler(rng.uniform(-0.3, 0.3, (B, 3))), rng.uniform([-10, -2, 0], [2, 2, 3], (B, 3)),
         rng.normal(0, 1, (B, 9))], axis=-1,
    )  # fmt: skip


def test_the_measurement_is_the_unit_vector_to_each_beacon():
    """Three components per beacon, unit norm to round-off, parallel to ``r_c`` (by hand: a beacon
    straight ahead of a level forward camera is (0, 0, 1); 3-4-5 off axis)."""
    spec = VisionSpec(kind="line_of_sight")
    assert spec.m == 3 * 8 and spec.measurement_names()[:3] == ("beacon1_los_x", "beacon1_los_y", "beacon1_los_z")
    sensor = VisionAiding(spec, mount_rotation("forward", 10.0), np.eye(spec.m), ins_layout())
    x = _state(np.random.default_rng(1), 4)
    b = sensor.h(x[:, None], np.zeros((4, 6)))[:, 0].reshape(4, 8, 3)
    np.testing.assert_allclose(np.linalg.norm(b, axis=-1), 1.0, rtol=0, atol=4 * EPS)
    r_c = line_of_sight(x[:, 0:4], x[:, 4:7], spec.beacon_array, sensor.C_cb)
    np.testing.assert_allclose(np.cross(b, r_c), 0.0, atol=1e-14 * np.abs(r_c).max())
    assert (np.einsum("bni,bni->bn", b, r_c) > 0).all()
    r = np.array([[0.0, 0.0, 7.0], [3.0, 0.0, 4.0]])
    np.testing.assert_allclose(project(r, "line_of_sight", 200.0, [320, 240]), [0, 0, 1, 0.6, 0, 0.8], rtol=1e-15)


def test_the_projection_jacobian_matches_finite_differences_and_is_tangent():
    """``(I − b bᵀ)/‖r‖`` against central differences (truncation ``h² ‖r‖⁻³`` and round-off
    ``eps/h``, both below 1e-9 at h = 1e-5 and ‖r‖ ≥ 1), and ``bᵀ J = 0``: the component along the
    line of sight does not move to first order."""
    rng = np.random.default_rng(2)
    r = rng.normal(0, 3, (5, 3)) + [0, 0, 6]
    J = projection_jacobian(r, "line_of_sight", 200.0)
    h = 1e-5
    fd = np.stack(
        [(project(r + h * e, "line_of_sight", 0, 0) - project(r - h * e, "line_of_sight", 0, 0)).reshape(5, 3) / (2 * h)
         for e in np.eye(3)], axis=-1,
    )  # fmt: skip
    np.testing.assert_allclose(J, fd, rtol=0, atol=1e-9)
    b = r / np.linalg.norm(r, axis=-1, keepdims=True)
    np.testing.assert_allclose(np.einsum("ni,nij->nj", b, J), 0.0, atol=10 * EPS)


@pytest.mark.parametrize("moving_platform", [False, True])
def test_error_state_jacobian_matches_finite_differences_on_the_manifold(moving_platform):
    """The analytic ``H_err`` (attitude and position blocks) against the model's central
    differences on the manifold (``fd_step``): round-off ``10 eps |y| / h`` plus truncation
    ``h² |y'''|``, with ``|y'''| ≲ 6/‖r‖³ ≤ 1`` at ranges beyond 2 m."""
    rng = np.random.default_rng(3)
    spec = VisionSpec(kind="line_of_sight", tilt_deg=20.0)
    layout = ins_layout(moving_platform)
    sensor = VisionAiding(
        spec, mount_rotation("forward", 20.0), np.eye(spec.m), layout, moving_platform=moving_platform
    )
    model = InsFilterModel(T, 9.81, np.eye(15), {"vision": sensor}, batch_size=3, platform_input=moving_platform)
    x = _state(rng, 3)
    u = np.zeros((3, 9 if moving_platform else 6))
    if moving_platform:
        u[:, 6:9] = rng.normal(0, 2, (3, 3))
        x[:, 4:7] += u[:, 6:9]
    H = model.H_err_analytic(x, u, "vision")
    H_fd = model.manifold_jacobian_fd(sensor.h, x, u, state_valued=False)
    step = model.fd_step
    np.testing.assert_allclose(H, H_fd, rtol=0, atol=10 * EPS / step + step**2)
    assert np.abs(H[:, :, 0:6]).max() > 1e-2 and np.abs(H[:, :, 6:]).max() == 0.0


@pytest.mark.parametrize(
    ("law", "factor"),
    [(NoiseLaw("gaussian"), 1.0), (NoiseLaw("contaminated", epsilon=0.1, variance_factor=5.0), 1.0 - 0.1 + 0.1 * 5.0)],
    ids=["gaussian", "contaminated"],
)
def test_noise_is_additive_per_component_with_the_sensor_law(law, factor):
    """``z − b`` has variance ``σ²`` (Gaussian) or ``σ² (1 − ε + ε f)`` (seed 004's eq. 63 with
    ε = 0.1, f = 5: 1.4 σ²) per component; and the contaminated draws are heavy-tailed: the
    fraction beyond 3σ is ``(1 − ε)·0.0027 + ε·P(|N| > 3/√5)`` ≈ 0.0203, checked to 5 binomial
    standard errors."""
    B, K1, sigma = 20, 401, 2e-3
    spec = VisionSpec(kind="line_of_sight", los_noise=sigma, noise_law=law)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (B, K1, 1))
    p = np.zeros((B, K1, 3))
    p[..., 2] = 1.0
    rec = measure_vision(spec, q, p, T, _rngs(4, B))
    ideal = project(line_of_sight(q, p, spec.beacon_array, mount_rotation("forward", 0.0)), "line_of_sight", 0, 0)
    e = rec.values[:, rec.available] - ideal[:, rec.available]
    assert e.shape[-1] == 24 and _variance_ok(e, factor * sigma**2)
    if law.kind == "contaminated":
        tail = 0.9 * 2 * norm.sf(3.0) + 0.1 * 2 * norm.sf(3.0 / np.sqrt(5.0))
        share = (np.abs(e) > 3 * sigma).mean()
        assert abs(share - tail) < 5 * np.sqrt(tail * (1 - tail) / e.size)


def test_availability_is_the_pixel_cameras():
    """The same frames as the pixel camera of the same spec (same field of view and range): every
    4th step at 25 Hz, none once the vehicle turns away from the beacons."""
    B, K1 = 3, 101
    q = np.tile([1.0, 0.0, 0.0, 0.0], (B, K1, 1))
    q[:, 60:] = quat.from_euler(np.array([0.0, 0.0, np.pi]))
    p = np.zeros((B, K1, 3))
    p[..., 2] = 1.0
    los = measure_vision(VisionSpec(kind="line_of_sight", rate=25.0), q, p, T, _rngs(5, B))
    pixel = measure_vision(VisionSpec(kind="pixel", rate=25.0), q, p, T, _rngs(5, B))
    np.testing.assert_array_equal(los.available, pixel.available)
    assert np.array_equal(np.flatnonzero(los.available), np.arange(0, 60, 4))
    assert np.isnan(los.values[:, ~los.available]).all() and not np.isnan(los.values[:, los.available]).any()


@pytest.mark.parametrize(
    ("override", "key", "allowed"),
    [
        ("sensor.vision.kind=unit", "sensor.vision.kind", "line_of_sight"),
        ("sensor.vision.los_noise=0", "sensor.vision.los_noise", "> 0"),
    ],
)
def test_bad_line_of_sight_settings_fail_before_any_work(override, key, allowed):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")) as err:
        validate(compose_config(["model=ins", "estimator=[mekf]", "sensor.vision.kind=line_of_sight", override]))
    assert allowed in str(err.value)


@pytest.mark.parametrize("estimator", ["mekf", "hckf"])
@pytest.mark.slow
def test_filters_on_line_of_sight_are_consistent_on_the_figure_eight(estimator):
    """Vision only (line of sight, Gaussian σ = 2.5e-3): at one step per second the NEES averaged
    over N runs is χ²(15 N)/N for a consistent filter; each of the 8 checked steps must lie in its
    two-sided band at level 1 − 0.01/8 (Bonferroni: a consistent filter fails with probability
    ≤ 1 %). A wrong Jacobian, R or measurement model makes the filter over- or under-confident."""
    cfg = compose_config(
        ["model=ins", "scenario=figure8", "runs=8", "duration=8", "seed=22", "estimator=[mekf]",
         "model.aiding=[vision]", "sensor.vision.kind=line_of_sight"]
    )  # fmt: skip
    validate(cfg)
    data = build_data(data_settings(cfg))
    result = run_estimator(estimator, build_estimator(estimator, {}, data.model), data, 1e6)
    assert not result.diverged.any()
    N, steps = 8, np.arange(100, 801, 100)
    alpha = 0.01 / steps.size
    lo, hi = chi2.ppf(alpha / 2, 15 * N) / N, chi2.ppf(1 - alpha / 2, 15 * N) / N
    nees = result.nees_mean_t[steps]
    assert ((nees > lo) & (nees < hi)).all(), (lo, hi, nees)
