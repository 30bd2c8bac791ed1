"""``experiment=seed004_landing`` (docs/seed004-landing.md): the approach onto the moving platform,
the beacons carried by the platform, the experiment's configuration, the seed's filter names
(``hckf`` is ``ckf5`` bit for bit, ``hf`` is the experiment's EKF plus the Huber update) and a tiny
run of every estimator it compares."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_config, compose_settings
from quadest.app.settings import data_settings
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.estimators.cubature import CKF5
from quadest.estimators.registry import build_estimator
from quadest.models.ins import InsFilterModel, ins_layout
from quadest.models.quadrotor_config import scenario
from quadest.montecarlo.streams import run_streams
from quadest.numerics import quaternion as quat
from quadest.quadrotor.scenarios import PlatformApproach
from quadest.runner import run_estimator
from quadest.sensors.vision import VisionAiding, VisionSpec, mount_rotation
from quadest.simulation.quadrotor_data import fly_scenario
from quadest.simulation.registry import build_data

EXPERIMENT = "experiment=seed004_landing"


def test_approach_reference_is_consistent_and_ends_above_the_platform():
    """The reference's velocity and acceleration are the derivatives of its position (central
    differences, truncation ``h² |r'''| / 6`` ≈ 1e-8 at h = 1e-4 s, round-off ``eps |r| / h`` ≈
    1e-10), and from ``approach_time`` on it is 2 m above the platform with its velocity."""
    sc = PlatformApproach()
    h = 1e-4
    for t in (1.0, 4.0, 12.3, 29.0):
        before, now, after = sc.reference(t - h), sc.reference(t), sc.reference(t + h)
        np.testing.assert_allclose((after.position - before.position) / (2 * h), now.velocity, atol=1e-6)
        np.testing.assert_allclose((after.velocity - before.velocity) / (2 * h), now.acceleration, atol=1e-6)
    end = sc.reference(sc.approach_time)
    np.testing.assert_allclose(end.position, sc.platform_position(sc.approach_time) + [0.0, 0.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(end.velocity, [2.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(sc.platform_position(0.0), [60.0, 0.0, 1.0])


@pytest.mark.slow
def test_the_flown_approach_starts_60_m_away_and_ends_2_m_above_the_moving_platform():
    """The truth the backstepping controller flies: 60 m from the platform at the start (up to the
    start scatter, σ = 0.05 m per axis: 5σ), and at the end 2 m above the platform's reference
    point, moving with it (the controller tracks the smooth reference to a few mm; 5 cm and
    5 cm/s are the margin of a landing pad, not a tuned number)."""
    cfg = compose_config([EXPERIMENT, "runs=2", "seed=4"])
    _, flown, truth = fly_scenario(data_settings(cfg), run_streams(4, 2))
    platform = flown.platform_position(truth.time)
    position, velocity = truth.state[..., 0:3], truth.state[..., 3:6]
    start_gap = np.linalg.norm((platform[0] - position[:, 0])[:, :2], axis=-1)
    np.testing.assert_allclose(start_gap, 60.0, atol=5 * 0.05 * np.sqrt(2))
    np.testing.assert_allclose(position[:, -1] - platform[-1], [[0.0, 0.0, 2.0]] * 2, atol=0.05)
    np.testing.assert_allclose(velocity[:, -1], [[2.0, 0.0, 0.0]] * 2, atol=0.05)


def test_beacon_on_the_moving_platform_projects_as_computed_by_hand():
    """Level vehicle at p = (10, 0, 5), platform at (12, 0, 3): relative position (−2, 0, 2). The
    beacon (0.5, −1, 0) of the platform frame is at (2.5, −1, −2) in the body frame; the forward
    camera sees (x, y, z) = (−y_b, −z_b, x_b) = (1, 2, 2.5), turned by the 30° tilt about x:
    y' = 2 cos 30° − 2.5 sin 30°, z' = 2 sin 30° + 2.5 cos 30°; pixel (320 + 200/z', 240 + 200 y'/z')."""
    spec = VisionSpec(beacons=[[0.5, -1.0, 0.0]] * 3, tilt_deg=30.0)
    sensor = VisionAiding(spec, mount_rotation("forward", 30.0), np.eye(spec.m), ins_layout(True), moving_platform=True)
    x = np.zeros((1, 16))
    x[0, 0:4] = [1.0, 0.0, 0.0, 0.0]
    x[0, 4:7] = [10.0, 0.0, 5.0]
    u = np.zeros((1, 9))
    u[0, 6:9] = [12.0, 0.0, 3.0]
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    y_c, z_c = 2.0 * c - 2.5 * s, 2.0 * s + 2.5 * c
    expected = np.tile([320.0 + 200.0 * 1.0 / z_c, 240.0 + 200.0 * y_c / z_c], 3)
    np.testing.assert_allclose(sensor.h(x[:, None], u)[0, 0], expected, rtol=1e-12)


def test_moving_platform_jacobian_matches_finite_differences():
    """The analytic Jacobian at the relative position against central differences on the manifold
    (as tests/test_ins.py: round-off ``10 eps |y| / h`` plus truncation ``h²``)."""
    rng = np.random.default_rng(5)
    spec = VisionSpec(tilt_deg=30.0, beacons=[[0.5, -1.0, 0.0], [2.5, 1.0, 0.0], [1.5, 0.0, 0.5]])
    sensor = VisionAiding(spec, mount_rotation("forward", 30.0), np.eye(spec.m), ins_layout(True), moving_platform=True)
    model = InsFilterModel(0.01, 9.81, np.eye(15), {"vision": sensor}, batch_size=2, platform_input=True)
    x = np.concatenate(
        [quat.from_euler(rng.uniform(-0.2, 0.2, (2, 3))), [[30.0, 0.5, 8.0], [40.0, -0.5, 6.0]], np.zeros((2, 9))],
        axis=-1,
    )
    u = np.concatenate([np.zeros((2, 6)), [[50.0, 0.0, 1.0], [55.0, 0.0, 1.0]]], axis=-1)
    step = 1e-5
    H_fd = model.manifold_jacobian_fd(sensor.h, x, u, state_valued=False)
    y = sensor.h(x[:, None], u)
    tol = 10 * np.finfo(float).eps * np.abs(y).max() / step + step**2 * np.abs(y).max()
    np.testing.assert_allclose(model.H_err_analytic(x, u, "vision"), H_fd, atol=max(tol, 1e-6))


def test_the_truth_camera_and_the_filters_camera_see_the_same_platform():
    """With (almost) no camera noise, each available frame equals the filters' ``h`` at the true
    state and the input's platform position: the truth and the filters put the beacons at the same
    place (a sign or frame slip on either side turns the lines of sight by whole degrees)."""
    cfg = compose_config([EXPERIMENT, "runs=2", "duration=1.0", "sensor.vision.los_noise=1e-12"])
    validate(cfg)
    data = build_data(data_settings(cfg))
    record, model = data.sensors["vision"], data.model
    assert model.nu == 9 and data.inputs.shape[-1] == 9
    frames = np.flatnonzero(record.available)
    np.testing.assert_array_equal(frames, np.arange(0, data.time.size, 5))  # 20 Hz, every beacon in view
    for k in frames[:5]:
        predicted = model.aiding["vision"].h(data.truth[:, k, None], data.inputs[:, k])[:, 0]
        np.testing.assert_allclose(record.values[:, k], predicted, atol=1e-10)


def test_the_experiment_composes_validates_and_carries_the_seed_settings():
    """Seed 004's numbers, converted by hand: 0.1 °/h = 0.1 π/180/3600 rad/s, 0.1 °/√h =
    0.1 π/180/60 rad/s/√Hz, 200 µg and 50 µg/√Hz at g = 9.80665 (the yaml keeps 3 digits: rtol 1e-3)."""
    cfg = compose_config([EXPERIMENT])
    validate(cfg)
    s, deg = cfg.sensor, np.pi / 180
    np.testing.assert_allclose(s.gyro.bias, 0.1 * deg / 3600, rtol=1e-3)
    np.testing.assert_allclose(s.gyro.white_noise, 0.1 * deg / 60, rtol=1e-3)
    np.testing.assert_allclose(s.accel.bias, 200e-6 * 9.80665, rtol=1e-3)
    np.testing.assert_allclose(s.accel.white_noise, 50e-6 * 9.80665, rtol=1e-3)
    assert (s.gyro.scale_factor, s.accel.scale_factor) == (0.01, 0.005)
    law = s.vision.noise_law
    assert (law.kind, law.epsilon, law.variance_factor) == ("contaminated", 0.1, 5.0)
    assert len(s.vision.beacons) == 8 and list(cfg.model.aiding) == ["vision"]
    assert s.vision.kind == "line_of_sight"
    assert set(cfg.estimator) == {"mekf", "hf", "hckf", "hhcf", "ckf", "huber_ckf"}
    assert (cfg.estimator.hckf.kind, cfg.estimator.hhcf.kind) == ("hckf", "hhcf")
    assert "robust" not in cfg.estimator.hckf and not cfg.estimator.mekf.reset_jacobian
    assert isinstance(scenario(data_settings(cfg).scenario), PlatformApproach)


def test_a_bad_approach_time_fails_before_any_work():
    with pytest.raises(ConfigError, match=r"scenario\.approach_time"):
        validate(compose_config([EXPERIMENT, "scenario.approach_time=0"]))


@pytest.mark.slow
def test_a_tiny_run_finishes_with_every_estimator():
    """Two runs of 0.5 s with every estimator of the experiment: none fails, every RMSE is finite."""
    cfg = compose_config([EXPERIMENT, "runs=2", "duration=0.5"])
    data = build_data(data_settings(cfg))
    for label, node in cfg.estimator.items():
        result = run_estimator(label, build_estimator(label, node, data.model), data, 1e6)
        assert not result.diverged.any(), (label, result.reasons)
        assert np.isfinite(result.sq_error_sum).all(), label


@pytest.fixture(scope="module")
def tiny_data():
    """Two runs of 0.5 s of the experiment (line of sight, contaminated noise)."""
    return build_data(compose_settings([EXPERIMENT, "runs=2", "duration=0.5"]))


def _run(name: str, data, **params):
    return run_estimator(name, build_estimator(name, params, data.model), data, 1e6)


def test_hckf_is_the_plain_fifth_degree_cubature_filter_bit_for_bit(tiny_data):
    """Seed 004's HCKF is ``ckf5`` under the seed's name: the same estimates, covariances and NEES,
    bit for bit (and not the Huber filter: ``hhcf`` differs under the contaminated noise)."""
    hckf, ckf5, hhcf = (_run(name, tiny_data) for name in ("hckf", "ckf5", "hhcf"))
    assert np.array_equal(hckf.sq_error_sum, ckf5.sq_error_sum)
    assert np.array_equal(hckf.nees_mean_t, ckf5.nees_mean_t, equal_nan=True)  # step 0 has no NEES: NaN in both
    assert not np.array_equal(hckf.sq_error_sum, hhcf.sq_error_sum)


def test_hckf_takes_no_huber_keys():
    """The seed's HCKF is never robust: a ``robust`` key is refused with one line naming it (the
    robust fifth-degree filter is ``hhcf``)."""
    with pytest.raises(ConfigError, match=r"estimator\.hckf\.robust.*allowed keys: augmented, kind"):
        validate(compose_config([EXPERIMENT, "+estimator.hckf.robust=true"]))


def test_hf_is_the_experiments_ekf_plus_the_huber_update(tiny_data):
    """With γ beyond any whitened residual ``hf`` keeps every Kalman update: it is the experiment's
    EKF (``mekf`` with ``reset_jacobian: false``) up to round-off (the two code paths solve the gain
    differently: relative 1e-9 after 50 steps), so HF vs EKF isolates the Huber update."""
    ekf = _run("mekf", tiny_data, reset_jacobian=False)
    hf = _run("hf", tiny_data, huber_threshold=1e12)
    np.testing.assert_allclose(hf.sq_error_sum, ekf.sq_error_sum, rtol=1e-9)
    assert not np.allclose(_run("hf", tiny_data).sq_error_sum, ekf.sq_error_sum, rtol=1e-6)


def test_a_camera_update_that_loses_definiteness_flags_only_its_runs():
    """The fifth-degree rule has negative weights for n = 15, so from large initial errors the
    camera's innovation covariance (24 × 24, a named sensor; the INS's primary measurement has
    none) can be indefinite in some runs. Those runs are flagged and the others keep their
    Cholesky factor (the fallback once had the primary measurement's 0 × 0 shape, and the
    exception failed every run of the batch)."""
    cfg = compose_config([EXPERIMENT, "runs=3", "duration=0.1"])
    est = CKF5(build_data(data_settings(cfg)).model)
    x0 = np.zeros((3, 16))
    x0[:, 0] = 1.0  # identity attitude quaternion
    est.initialize(x0, np.broadcast_to(np.eye(15), (3, 15, 15)))
    Pyy = np.broadcast_to(2.0 * np.eye(24), (3, 24, 24)).copy()
    Pyy[1, 0, 0] = -1.0
    Sy = est._innovation_factor(Pyy)
    np.testing.assert_allclose(Sy[[0, 2]], np.sqrt(2.0) * np.eye(24)[None].repeat(2, 0), rtol=1e-15)
    assert np.isfinite(Sy).all() and Sy.shape == (3, 24, 24)
    assert est.failed.tolist() == [False, True, False]
    assert est.failure_reasons[1] == "innovation covariance not positive definite"
