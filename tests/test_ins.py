"""``model=ins`` and its navigation sensors (GPS, barometer, camera): draws with the configured
statistics, rates and availability, common random numbers, Jacobians on the manifold, the
strapdown mechanisation against closed forms, the camera against hand-computed projections, and
χ² consistency on the figure eight."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.estimators.registry import build_estimator
from quadest.models.ins import InsFilterModel, ins_layout
from quadest.montecarlo.streams import STREAMS, run_streams
from quadest.numerics import quaternion as quat
from quadest.runner import run_estimator
from quadest.sensors.barometer import BarometerSpec, measure_barometer
from quadest.sensors.gps import GpsAiding, GPSSpec, measure_gps
from quadest.sensors.magnetometer import MagnetometerAiding
from quadest.sensors.mimu import TriadErrors
from quadest.sensors.vision import (
    VisionAiding,
    VisionSpec,
    line_of_sight,
    measure_vision,
    mount_rotation,
    project,
)
from quadest.simulation.registry import build_data

T = 0.01
# The streams as they were before the navigation sensors were appended (spawn order).
BEFORE_NAVIGATION = (
    "start", "accel_errors", "gyro_errors", "accel_noise", "gyro_noise", "encoder", "initial", "process",
    "measurement", "estimator", "state_sensor", "mag_errors", "mag_noise",
)  # fmt: skip


def _rngs(seed: int, runs: int) -> list[np.random.Generator]:
    return [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(runs)]


def _variance_ok(samples: np.ndarray, sigma2: float, z: float = 4.5) -> bool:
    """``|s² − σ²| < z σ² √(2/(N−1))``: the standard error of a normal sample variance, at z = 4.5
    (a false alarm about once in 10⁵)."""
    n = samples.size
    return abs(samples.var(ddof=1) - sigma2) < z * sigma2 * np.sqrt(2.0 / (n - 1))


def _mean_ok(samples: np.ndarray, sigma: float, z: float = 4.5) -> bool:
    return abs(samples.mean()) < z * sigma / np.sqrt(samples.size)


# --- draws: statistics, rates, availability ---


def test_gps_white_noise_rate_and_latency():
    B, K1 = 40, 1001
    t = np.arange(K1) * T
    p = np.stack([np.sin(t), np.cos(t), 0.1 * t], -1)[None].repeat(B, 0)
    v = np.stack([np.cos(t), -np.sin(t), 0.1 + 0 * t], -1)[None].repeat(B, 0)
    spec = GPSSpec(rate=5.0, horizontal_noise=0.7, vertical_noise=1.3, velocity_noise=0.05)
    rec = measure_gps(spec, p, v, T, _rngs(1, B))
    assert np.array_equal(np.flatnonzero(rec.available), np.arange(0, K1, 20))  # 5 Hz at T = 0.01 s
    assert np.isnan(rec.values[:, ~rec.available]).all()
    err = rec.values[:, rec.available] - np.concatenate([p, v], -1)[:, rec.available]
    for j, s in enumerate([0.7, 0.7, 1.3, 0.05, 0.05, 0.05]):  # the configured levels, not spec.white_std()
        assert _mean_ok(err[..., j], s) and _variance_ok(err[..., j], s**2), j
    late = measure_gps(replace(spec, latency=0.05), p, v, T, _rngs(1, B))
    delayed = np.concatenate([p, v], -1)[:, np.arange(0, K1, 20) - 5]
    white = rec.values[:, rec.available] - np.concatenate([p, v], -1)[:, rec.available]
    np.testing.assert_allclose(late.values[:, late.available][:, 1:], (delayed + white)[:, 1:], atol=1e-12)


@pytest.mark.slow
def test_gps_drift_is_stationary_gauss_markov():
    """One sample per run at two steps 1 s apart: variance σ² at each and correlation
    φ = exp(−1 s / τ) between them (runs independent)."""
    B, K1 = 4000, 201
    spec = GPSSpec(rate=100.0, horizontal_noise=1e-9, vertical_noise=1e-9, position_drift=2.0, drift_time=4.0)
    rec = measure_gps(spec, np.zeros((B, K1, 3)), np.zeros((B, K1, 3)), T, _rngs(2, B))
    a, b = rec.values[:, 100, 0], rec.values[:, 200, 0]
    assert _variance_ok(a, 4.0) and _variance_ok(b, 4.0)
    rho, phi = np.corrcoef(a, b)[0, 1], np.exp(-1.0 / 4.0)
    assert abs(rho - phi) < 4.5 * (1 - phi**2) / np.sqrt(B)  # std of a sample correlation


def test_barometer_error_classes():
    B, K1 = 3000, 101
    z = np.linspace(0.0, 2.0, K1)[None].repeat(B, 0)
    white = measure_barometer(BarometerSpec(rate=50.0, bias_random_walk=0.0), z, T, _rngs(3, B))
    assert np.array_equal(np.flatnonzero(white.available), np.arange(0, K1, 2))
    e = white.values[:, white.available, 0] - z[:, white.available]
    assert _mean_ok(e, 0.1) and _variance_ok(e, 0.01)
    spec = BarometerSpec(rate=100.0, white_noise=1e-9, bias=0.5, bias_random_walk=0.2, scale_factor=0.0)
    walk = measure_barometer(spec, z, T, _rngs(4, B)).values[..., 0] - z
    assert _variance_ok(walk[:, 0], 0.25)  # turn-on bias, across runs
    assert _variance_ok(walk[:, 100] - walk[:, 0], 0.2**2 * 1.0)  # random walk after 1 s
    scale = measure_barometer(
        BarometerSpec(rate=100.0, white_noise=1e-9, bias_random_walk=0.0, scale_factor=0.05), z, T, _rngs(5, B)
    ).values[..., 0]
    assert _variance_ok(scale[:, -1] / 2.0 - 1.0, 0.05**2)


def test_vision_noise_rate_and_dropped_frames():
    B, K1 = 30, 201
    spec = VisionSpec(rate=20.0, pixel_noise=0.8)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (B, K1, 1))
    p = np.zeros((B, K1, 3))
    p[..., 2] = 1.0
    rec = measure_vision(spec, q, p, T, _rngs(6, B))
    assert np.array_equal(np.flatnonzero(rec.available), np.arange(0, K1, 5))
    ideal = project(line_of_sight(q, p, spec.beacon_array, mount_rotation("forward", 0.0)), "pixel", 200.0, [320, 240])
    e = rec.values[:, rec.available] - ideal[:, rec.available]
    assert _mean_ok(e, 0.8) and _variance_ok(e, 0.64)
    turned = quat.from_euler(np.array([0.0, 0.0, np.pi]))  # facing away from the beacons from step 100 on
    q[:, 100:] = turned
    partly = measure_vision(spec, q, p, T, _rngs(6, B))
    assert partly.available[:100].sum() == 20 and not partly.available[100:].any()
    assert np.isnan(partly.values[:, 100:]).all()


def test_new_streams_are_appended_and_old_ones_keep_their_draws():
    assert STREAMS[: len(BEFORE_NAVIGATION)] == BEFORE_NAVIGATION
    streams = run_streams(7, 2)
    for name in (*BEFORE_NAVIGATION, "gps", "barometer", "vision"):
        for i in range(2):
            ref = np.random.default_rng(np.random.SeedSequence(7, spawn_key=(i, STREAMS.index(name))))
            np.testing.assert_array_equal(streams[name][i].standard_normal(4), ref.standard_normal(4))


def _ins_data(*overrides: str):
    cfg = compose_config(["model=ins", "runs=2", "duration=1.0", "seed=3", "estimator=[mekf]", *overrides])
    validate(cfg)
    return build_data(data_settings(cfg))


@pytest.mark.slow
def test_common_random_numbers_across_sensors_and_estimators():
    full = _ins_data()
    only_vision = _ins_data("model.aiding=[vision]")
    np.testing.assert_array_equal(full.inputs, only_vision.inputs)  # adding sensors moves no MIMU draw
    np.testing.assert_array_equal(full.sensors["vision"].values, only_vision.sensors["vision"].values)
    np.testing.assert_array_equal(full.x0, only_vision.x0)
    gps = full.sensors["gps"]
    i, k = 1, 20  # the GPS sample of run 1 at step 20 is truth + the first white draws of its own stream
    rng = np.random.default_rng(np.random.SeedSequence(3, spawn_key=(i, STREAMS.index("gps"))))
    rng.standard_normal((full.time.size, 3))  # the drift's normals come first
    white = rng.standard_normal((full.time.size, 6))[k] * GPSSpec().white_std()
    truth = np.concatenate([full.truth[i, k, 4:7], full.truth[i, k, 7:10]])
    np.testing.assert_allclose(gps.values[i, k], truth + white, atol=1e-12)
    before = {name: rec.values.copy() for name, rec in full.sensors.items()}
    results = [run_estimator(name, build_estimator(name, {}, full.model), full, 1e6) for name in ("mekf", "ckf")]
    for name, rec in full.sensors.items():  # no estimator changes what the next one sees
        np.testing.assert_array_equal(rec.values, before[name])
    counts = [{s: c for s, (_, c) in r.sensor_nis.items()} for r in results]
    for s in full.sensors:
        np.testing.assert_array_equal(counts[0][s], counts[1][s])  # same samples, same updates


# --- the camera against hand-computed projections ---


def test_camera_projection_by_hand():
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    beacon = np.array([[10.0, 2.0, 1.0]])
    r_c = line_of_sight(identity, np.zeros(3), beacon, mount_rotation("forward", 0.0))
    np.testing.assert_allclose(r_c, [[-2.0, -1.0, 10.0]])  # right = −y_b, down = −z_b, axis = x_b
    np.testing.assert_allclose(project(r_c, "pixel", 200.0, [320.0, 240.0]), [280.0, 220.0])
    np.testing.assert_allclose(project(r_c, "bearing", 200.0, [320.0, 240.0]), [np.arctan(-0.2), np.arctan(-0.1)])
    yawed = quat.from_euler(np.array([0.0, 0.0, np.pi / 2]))  # body x along earth y
    r_c = line_of_sight(yawed, np.zeros(3), np.array([[0.0, 10.0, 0.0]]), mount_rotation("forward", 0.0))
    np.testing.assert_allclose(project(r_c, "pixel", 200.0, [320.0, 240.0]), [320.0, 240.0], atol=1e-12)
    down = line_of_sight(identity, np.array([0.0, 0.0, 5.0]), np.array([[1.0, 0.0, 0.0]]), mount_rotation("down", 0))
    np.testing.assert_allclose(project(down, "pixel", 200.0, [320.0, 240.0]), [320.0, 200.0])
    np.testing.assert_allclose(mount_rotation("forward", 90.0), mount_rotation("down", 0.0), atol=1e-15)


# --- Jacobians on the manifold ---


def _random_ins_model(chart: str = "rotation_vector", B: int = 3):
    rng = np.random.default_rng(11)
    errors = [
        TriadErrors(
            np.eye(3) + 0.02 * rng.standard_normal((B, 3, 3)), 0.01 * rng.standard_normal((B, 3)), np.zeros((B, 3))
        )
        for _ in range(3)
    ]
    vision, layout = VisionSpec(), ins_layout()
    aiding = {
        "gps": GpsAiding(GPSSpec(latency=0.1), 0.1, np.eye(6), layout),
        "vision": VisionAiding(vision, mount_rotation("forward", 10.0), np.eye(vision.m), layout),
        "vision_bearing": VisionAiding(VisionSpec(kind="bearing"), mount_rotation("forward", 10.0), np.eye(16), layout),
        "magnetometer": MagnetometerAiding(np.array([20.0, 0.0, -45.0]), errors[2], np.eye(3), layout),
    }
    model = InsFilterModel(T, 9.81, np.eye(15), aiding, errors[0], errors[1], chart=chart, batch_size=B)
    x = np.concatenate(
        [
            quat.from_euler(rng.uniform(-0.5, 0.5, (B, 3))),
            rng.uniform(-2, 2, (B, 3)),
            rng.normal(0, 1, (B, 3)),
            0.05 * rng.standard_normal((B, 3)),
            0.3 * rng.standard_normal((B, 3)),
        ],
        axis=-1,
    )
    u = np.concatenate([rng.normal(0, 2.0, (B, 3)), rng.normal(0, 3.0, (B, 3)) + [0, 0, 9.81]], axis=-1)
    return model, x, u


def _fd_tolerance(values: np.ndarray, step: float) -> float:
    """Central-difference error bound: round-off ``≈ 10 eps |y| / h`` plus truncation ``≈ h² |y'''|``
    (second-order smooth functions of O(1) curvature at the model's scales)."""
    return 10.0 * np.finfo(float).eps * float(np.abs(values).max()) / step + 1e3 * step**2


@pytest.mark.parametrize("chart", ["rotation_vector", "mrp"])
def test_error_state_jacobians_match_finite_differences_on_the_manifold(chart):
    model, x, u = _random_ins_model(chart)
    F = model.F_err_analytic(x, u)
    F_fd = model.manifold_jacobian_fd(model.f, x, u, state_valued=True)
    np.testing.assert_allclose(F, F_fd, rtol=0, atol=_fd_tolerance(x, model.fd_step))
    for name, sensor in model.aiding.items():
        H_fd = model.manifold_jacobian_fd(sensor.h, x, u, state_valued=False)
        y = sensor.h(x[:, None], u)
        np.testing.assert_allclose(model.H_err_analytic(x, u, name), H_fd, rtol=1e-6, atol=_fd_tolerance(y, 1e-6))


def test_charts_round_trip_and_agree_to_first_order():
    for chart in ("rotation_vector", "mrp"):
        model, x, _ = _random_ins_model(chart)
        dx = 0.3 * np.random.default_rng(5).standard_normal((3, 15))
        np.testing.assert_allclose(model.boxminus(model.boxplus(x, dx), x), dx, atol=1e-12)
    rv, x, _ = _random_ins_model("rotation_vector")
    mrp, _, _ = _random_ins_model("mrp")
    small = 1e-4 * np.ones((3, 15))
    angle_gap = rv.boxminus(mrp.boxplus(x, small), x) - small  # e(δ) = exp(δ) + O(|δ|³)
    assert np.abs(angle_gap).max() < 1e-11


@pytest.mark.parametrize("chart", ["rotation_vector", "mrp"])
@pytest.mark.parametrize("family", ["ckf", "srukf", "ekf", "ukf"])
def test_sigma_point_error_state_filters_equal_the_mekf_on_a_nearly_linear_case(family, chart):
    """One predict and the camera, GPS and magnetometer updates from a spread σ = 1e-3 (rad, m,
    m/s, ...): the sigma-point filters differ from the MEKF's linearisation only by the model's
    second-order terms over the spread, O(σ²) in the mean and relatively in the covariance, with a
    coefficient of the order of the model's curvature at these scales (≤ 10). The MEKF runs without
    the reset Jacobian, which the family does not apply (itself a second-order term)."""
    sigma = 1e-3
    model, x, u = _random_ins_model(chart)
    model.Q = (0.1 * sigma) ** 2 * np.eye(15)
    P0 = np.broadcast_to(sigma**2 * np.eye(15), (x.shape[0], 15, 15))
    truth = model.boxplus(model.f(x[:, None], u)[:, 0], sigma * np.random.default_rng(3).standard_normal((3, 15)))
    out = {}
    for name, params in (("mekf", {"reset_jacobian": False}), (family, {})):
        est = build_estimator(name, params, model)
        est.initialize(x.copy(), P0.copy())
        est.predict(u)
        est.update(np.zeros((x.shape[0], 0)), u)  # the empty primary measurement, as the runner sends it
        for sensor in ("vision", "gps", "magnetometer"):
            est.update(model.aiding[sensor].h(truth[:, None], u)[:, 0], u, sensor=sensor)
        out[name] = est.mean.copy(), est.covariance.copy()
    assert np.abs(model.boxminus(out[family][0], out["mekf"][0])).max() < 10 * sigma**2
    assert np.abs(out[family][1] - out["mekf"][1]).max() < 10 * sigma**2 * np.abs(out["mekf"][1]).max()


# --- strapdown mechanisation against closed forms ---


def _propagate(model: InsFilterModel, x: np.ndarray, u: np.ndarray, steps: int) -> np.ndarray:
    for _ in range(steps):
        x = model.f(x[:, None], u)[:, 0]
    return x


def test_strapdown_is_exact_for_constant_rate_and_specific_force_along_the_axis():
    """``q(t) = q0 ⊗ exp(ω t)``; ``R(q(t)) f = R(q0) f`` when ``f ∥ ω``, so ``a = R(q0) f + g_e`` is
    constant: ``v = v0 + a t``, ``p = p0 + v0 t + a t²/2`` exactly."""
    model = InsFilterModel(T, 9.81, np.eye(15), {})
    q0 = quat.from_euler(np.array([0.3, -0.2, 1.0]))
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    omega, f = 0.8 * axis, 11.0 * axis
    x0 = np.concatenate([q0, [1.0, -2.0, 3.0], [0.5, 0.1, -0.3], np.zeros(6)])[None]
    steps = 1000
    x = _propagate(model, x0, np.concatenate([omega, f])[None], steps)
    t = steps * T
    a = quat.rotate(q0, f) + [0.0, 0.0, -9.81]
    np.testing.assert_allclose(quat.boxminus(x[0, :4], quat.multiply(q0, quat.exp(omega * t))), 0, atol=1e-12)
    np.testing.assert_allclose(x[0, 7:10], x0[0, 7:10] + a * t, rtol=1e-12, atol=1e-11)
    np.testing.assert_allclose(x[0, 4:7], x0[0, 4:7] + x0[0, 7:10] * t + 0.5 * a * t**2, rtol=1e-12, atol=1e-10)


def test_strapdown_midpoint_attitude_error_is_within_the_midpoint_rule_bound():
    """Yaw rate w, specific force c along body x: ``v(t) = (c/w)(sin wt, 1 − cos wt, 0) + g_e t``.
    The mechanisation applies the midpoint rule to ``∫ R(q(s)) f ds``, error at most
    ``t T² w² c / 24``; a first-order mechanisation (attitude at the start of the step) is off by
    about ``t w c T / 2``, 300 times more here."""
    model = InsFilterModel(T, 9.81, np.eye(15), {})
    w, c, steps = 1.0, 5.0, 500
    t = steps * T
    x = _propagate(model, np.concatenate([[1.0, 0, 0, 0], np.zeros(12)])[None], np.array([[0, 0, w, c, 0, 0]]), steps)
    v = np.array([c / w * np.sin(w * t), c / w * (1 - np.cos(w * t)), -9.81 * t])
    assert np.abs(x[0, 7:10] - v).max() <= t * T**2 * w**2 * c / 24.0 * 1.01


# --- consistency on the figure eight ---


@pytest.mark.parametrize("estimator", ["mekf", "ckf"])
@pytest.mark.slow
def test_nees_on_the_figure_eight_lies_in_its_chi2_band(estimator):
    """At one step per second, the NEES averaged over N runs is χ²(15 N)/N when the filter is
    consistent (runs independent). Each of the 10 checked steps must lie in its two-sided band at
    level 1 − 0.01/10 (Bonferroni: a consistent filter fails with probability ≤ 1 %)."""
    cfg = compose_config(["model=ins", "scenario=figure8", "runs=8", "duration=10", "seed=21", "estimator=[mekf]"])
    data = build_data(data_settings(cfg))
    est = build_estimator(estimator, {}, data.model)
    result = run_estimator(estimator, est, data, 1e6)
    assert not result.diverged.any()
    N, steps = 8, np.arange(100, 1001, 100)
    alpha = 0.01 / steps.size
    lo, hi = chi2.ppf(alpha / 2, 15 * N) / N, chi2.ppf(1 - alpha / 2, 15 * N) / N
    nees = result.nees_mean_t[steps]
    assert ((nees > lo) & (nees < hi)).all(), (lo, hi, nees)


# --- configuration errors ---


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("sensor.gps.rate=3.0", "sensor.gps.rate"),
        ("sensor.vision.kind=fisheye", "sensor.vision.kind"),
        ("model.aiding=[gps,lidar]", "model.aiding"),
        ("model.attitude_chart=euler", "model.attitude_chart"),
        ("sensor.barometer.white_noise=0", "sensor.barometer.white_noise"),
    ],
)
def test_bad_navigation_settings_fail_before_any_work(override, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        validate(compose_config(["model=ins", "estimator=[mekf]", override]))
