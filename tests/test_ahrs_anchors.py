"""The ahrs anchors (Madgwick, Mahony, the ahrs EKF) as quadest estimators: registered through the
plugin contract, frame conventions right in NED (a PX4 log) and z-up (the simulation), the
magnetometer step made from the same start as the accelerometer step, and no covariance handled
as "NEES unavailable", not as divergence."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ahrs")

from quadest.estimators.ahrs_anchors import AhrsEKF, AhrsMadgwick, AhrsMahony
from quadest.estimators.registry import build_estimator, builtin_estimators, contract_problems
from quadest.models.attitude import AttitudeFilterModel
from quadest.montecarlo import MonteCarloData
from quadest.numerics import quaternion as quat
from quadest.runner import run_estimator
from quadest.sensors.record import SensorRecord

ANCHORS = {"madgwick": AhrsMadgwick, "mahony": AhrsMahony, "ahrs_ekf": AhrsEKF}
T = 0.01
FIELD_NED = np.array([21.5, 0.0, 43.1])  # uT, the shipped log's field


def _model(gravity_z: float, field: np.ndarray) -> AttitudeFilterModel:
    return AttitudeFilterModel(T, [0.0, 0.0, gravity_z], field, 1e-6 * np.eye(9), 0.01 * np.eye(3), np.eye(3))


def _static_data(model: AttitudeFilterModel, angles: np.ndarray, gyro_bias: np.ndarray, steps: int) -> MonteCarloData:
    """A vehicle at rest at ``angles`` (roll, pitch, yaw), noise-free sensors, a gyro bias; the
    filters start 5° off about each body axis."""
    x = AttitudeFilterModel.truth_state(angles, gyro_bias, np.zeros(3))
    truth = np.tile(x, (1, steps + 1, 1))
    accel = model.h(x[None, None], np.zeros((1, 6)))[0, 0]
    mag = model.h_mag(x[None, None], np.zeros((1, 6)))[0, 0]
    return MonteCarloData(
        model=model, time=T * np.arange(steps + 1), truth=truth, companion_truth=np.zeros((1, steps + 1, 0)),
        inputs=np.tile(np.concatenate([gyro_bias, np.zeros(3)]), (1, steps + 1, 1)),
        measurements=np.tile(accel, (1, steps + 1, 1)),
        x0=model.boxplus(x, np.radians([5.0, -5.0, 5.0] + [0.0] * 6))[None], P0=np.eye(9) * 0.01,
        companion0=np.zeros((1, 0)),
        estimator_seeds=[np.random.SeedSequence(0)],
        sensors={"mag": SensorRecord(np.tile(mag, (1, steps + 1, 1)), np.arange(steps + 1) % 2 == 0)},
    )  # fmt: skip


def test_the_anchors_are_registered_estimators_meeting_the_contract():
    specs = builtin_estimators()
    for name, cls in ANCHORS.items():
        assert specs[name].cls is cls and not contract_problems(cls)
        assert "no_covariance" in cls.capabilities


@pytest.mark.parametrize("name", sorted(ANCHORS))
@pytest.mark.parametrize(("gravity_z", "field"), [(9.81, FIELD_NED), (-9.81, FIELD_NED * [1, 1, -1])])
@pytest.mark.slow
def test_each_anchor_converges_to_the_true_attitude_at_rest(name, gravity_z, field):
    """NED (gravity +z, as in a PX4 log) and z up (the simulation): from 5° off, every anchor must
    settle on roll 10°, pitch −20°, yaw 60°. A missing accelerometer flip for NED (a 180° tilt
    error), or Mahony's north-on-+y frame left unconverted (a 90° yaw error), fails here."""
    model = _model(gravity_z, field)
    angles = np.radians([10.0, -20.0, 60.0])
    params = {  # faster than the defaults, to settle within the 20 s (Mahony's integral would take minutes)
        "ahrs_ekf": {"var_gyr": 1e-4, "var_acc": 1e-2, "var_mag": 1e-2},
        "mahony": {"k_P": 3.0, "k_I": 0.01},
    }.get(name, {})
    tiny_bias = np.full(3, 1e-4)  # ahrs skips a step whose gyro sample is exactly zero
    data = _static_data(model, angles, tiny_bias, 2000)
    est = build_estimator(name, {"kind": name, **params}, model)
    result = run_estimator(name, est, data, divergence_bound=50.0, saved_runs=1)
    assert not result.diverged.any(), result.reasons
    final = result.saved["estimate"][0, -1]
    angle_error = np.degrees(np.linalg.norm(quat.boxminus(final[:4], data.truth[0, -1, :4])))
    assert angle_error < 0.5, (name, angle_error)


@pytest.mark.slow
def test_mahony_estimates_the_gyro_bias_and_reports_it():
    model = _model(9.81, FIELD_NED)
    bias = np.array([0.01, -0.02, 0.015])
    data = _static_data(model, np.radians([5.0, 5.0, 30.0]), bias, 6000)
    est = build_estimator("mahony", {"kind": "mahony", "k_P": 3.0, "k_I": 1.0}, model)  # settles within the 60 s
    result = run_estimator("mahony", est, data, divergence_bound=50.0, saved_runs=1)
    # ahrs' Mahony subtracts its b from the gyro: b converges to the bias within its time constant
    np.testing.assert_allclose(result.saved["estimate"][0, -1, 4:7], bias, atol=1e-4)


@pytest.mark.parametrize("name", sorted(ANCHORS))
def test_a_magnetometer_sample_remakes_the_step_as_one_marg_step_from_the_same_start(name):
    """update(acc) then update(mag, sensor="mag") must equal the ahrs MARG step from the state
    before the step, on a fresh ahrs object (the IMU-only step must leave no trace)."""
    model = _model(9.81, FIELD_NED)
    rng = np.random.default_rng(7)
    est = ANCHORS[name](model)
    reference = ANCHORS[name](model)
    x0 = AttitudeFilterModel.truth_state(np.radians([3.0, -4.0, 20.0]), np.zeros(3), np.zeros(3))
    est.initialize(x0, np.eye(9))
    reference.initialize(x0, np.eye(9))
    for _ in range(5):
        gyro, acc, mag = rng.normal(0, 0.1, 3), np.array([0.3, -0.2, -9.8]), FIELD_NED + rng.normal(0, 1, 3)
        est.predict(np.concatenate([gyro, np.zeros(3)]))
        est.update(acc, np.zeros(6))
        est.update(mag, np.zeros(6), sensor="mag")
        reference._gyro = gyro
        reference.x[:4] = reference._step(reference.x[:4], -acc, mag)
        np.testing.assert_allclose(est.mean, reference.mean, rtol=0, atol=1e-15)


def test_no_covariance_means_nees_unavailable_not_divergence():
    model = _model(9.81, FIELD_NED)
    data = _static_data(model, np.radians([1.0, 2.0, 3.0]), np.full(3, 1e-4), 50)
    result = run_estimator("mahony", build_estimator("mahony", {"kind": "mahony"}, model), data, 50.0, saved_runs=1)
    assert not result.diverged.any(), result.reasons
    assert np.isnan(result.mean_nees).all() and result.nees_steps[0] == 0
    assert np.isnan(result.saved["std"]).all()


@pytest.mark.parametrize(("name", "params"), [("madgwick", {"gain_imu": 0.0}), ("mahony", {"k_P": -1.0}),
                                              ("ahrs_ekf", {"var_acc": 0.0})])  # fmt: skip
def test_bad_parameters_are_refused(name, params):
    with pytest.raises(ValueError, match=name):
        ANCHORS[name](_model(9.81, FIELD_NED), **params)


def test_a_model_that_is_not_the_attitude_model_is_refused():
    from quadest.conformance import linear_gaussian_problem

    with pytest.raises(ValueError, match="attitude model"):
        AhrsMadgwick(linear_gaussian_problem()[0])
