"""The shared quadrotor: physics identities, filter-model Jacobians, sensors and the controller."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.conformance import check_model
from quadest.models.quadrotor_config import quadrotor_params
from quadest.montecarlo.streams import run_streams
from quadest.quadrotor.controller import BacksteppingController, BacksteppingGains
from quadest.quadrotor.dynamics import (
    body_rates,
    euler_angle_accel,
    euler_rates,
    rk4_step,
    rotor_inputs,
    specific_force,
    translational_accel,
    truth_derivative,
)
from quadest.quadrotor.kinematics import rate_matrix, rate_matrix_inv, rotation
from quadest.quadrotor.params import QuadrotorParams
from quadest.quadrotor.scenario_registry import builtin_scenario_classes
from quadest.quadrotor.simulate import simulate_truth
from quadest.sensors.encoders import encoder_resolution, measure_rotor_speeds
from quadest.sensors.mimu import TriadSpec, draw_triad_errors, measure_triad
from quadest.simulation.quadrotor_data import build_quadrotor_data

P = QuadrotorParams()


def random_states(seed: int, count: int = 20) -> np.ndarray:
    rng = np.random.default_rng(seed)
    s = np.zeros((count, 16))
    s[:, 0:3] = rng.normal(0, 1, (count, 3))
    s[:, 3:6] = rng.normal(0, 2, (count, 3))
    s[:, 6:9] = rng.uniform(-0.6, 0.6, (count, 3))
    s[:, 9:12] = rng.normal(0, 1, (count, 3))
    s[:, 12:16] = rng.uniform(150, 300, (count, 4))
    return s


# --- physics -------------------------------------------------------------------------------


def test_hover_equilibrium_holds():
    state = np.zeros((1, 16))
    state[:, 2] = 1.0
    state[:, 12:16] = P.hover_speed
    d = truth_derivative(P, state, state[:, 12:16])
    np.testing.assert_allclose(d, 0.0, atol=1e-12)
    assert abs(P.hover_speed - 225.7) < 0.1  # sqrt(m g / 4 b) with the OS4 m and b (docs/sources.md)


def test_drag_free_energy_balance():
    """Without drag, d/dt(½ m|v|² + m g z) = U1 (R e_z)·v, and d/dt(½ ωᵀIω) = ωᵀτ: the
    gyroscopic terms −ω×Iω and −Jr(ω×e_z)Ωr do no work."""
    p = QuadrotorParams(translational_drag=(0, 0, 0), rotational_drag=(0, 0, 0))
    s = random_states(1)
    d = truth_derivative(p, s, s[:, 12:16])
    U, _ = rotor_inputs(p, s[:, 12:16])
    v, omega = s[:, 3:6], s[:, 9:12]
    translational = p.mass * np.sum(v * d[:, 3:6], -1) + p.mass * p.gravity * v[:, 2]
    thrust_power = U[:, 0] * np.sum(rotation(s[:, 6:9])[:, :, 2] * v, -1)
    np.testing.assert_allclose(translational, thrust_power, rtol=1e-10, atol=1e-10)
    rotational = np.sum(omega * p.inertia_vec * d[:, 9:12], -1)
    np.testing.assert_allclose(rotational, np.sum(omega * U[:, 1:], -1), rtol=1e-10, atol=1e-12)


def test_rotor_inputs_match_mixer():
    s = random_states(2)[:, 12:16]
    U, omega_r = rotor_inputs(P, s)
    np.testing.assert_allclose(U, (s**2) @ P.mixer.T, rtol=1e-13)
    np.testing.assert_allclose(omega_r, s[:, 0] - s[:, 1] + s[:, 2] - s[:, 3])


def test_elementwise_kinematics_match_matrix_forms():
    s = random_states(3)
    ang, v, omega = s[:, 6:9], s[:, 3:6], s[:, 9:12]
    R, W, Winv = rotation(ang), rate_matrix(ang), rate_matrix_inv(ang)
    np.testing.assert_allclose(W @ Winv, np.broadcast_to(np.eye(3), W.shape), atol=1e-12)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(euler_rates(ang, omega), np.einsum("bij,bj->bi", Winv, omega), rtol=1e-12)
    np.testing.assert_allclose(body_rates(ang, euler_rates(ang, omega)), omega, rtol=1e-12, atol=1e-12)
    U, _ = rotor_inputs(P, s[:, 12:16])
    vdot = translational_accel(P, ang, v, U[:, 0])
    expected = R[:, :, 2] * U[:, :1] / P.mass - P.kt * v / P.mass - [0, 0, P.gravity]
    np.testing.assert_allclose(vdot, expected, rtol=1e-12, atol=1e-12)
    f_b = np.einsum("bji,bj->bi", R, vdot + np.array([0.0, 0.0, P.gravity]))  # Rᵀ (v̇ + g e_z)
    np.testing.assert_allclose(specific_force(P, ang, v, U[:, 0]), f_b, rtol=1e-10, atol=1e-10)


def test_euler_angle_accel_is_the_time_derivative_of_euler_rates():
    """Thesis eq. 5.31 checked against a central difference of Θ̇(t) along the true motion."""
    s = random_states(4, 5)
    s[:, 12:16] = P.hover_speed  # motors at their command: no motor dynamics in the difference
    h = 1e-5
    ahead = rk4_step(P, s, s[:, 12:16], h)
    behind = rk4_step(P, s, s[:, 12:16], -h)
    numeric = (euler_rates(ahead[:, 6:9], ahead[:, 9:12]) - euler_rates(behind[:, 6:9], behind[:, 9:12])) / (2 * h)
    analytic = euler_angle_accel(P, s[:, 6:9], euler_rates(s[:, 6:9], s[:, 9:12]), s[:, 12:16])
    np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-6)


# --- filter models ---------------------------------------------------------------------------


@pytest.mark.parametrize("formulation", ["thesis", "augmented"])
@pytest.mark.parametrize("calibrated", [True, False])
@pytest.mark.slow
def test_jacobians_match_finite_differences(formulation, calibrated):
    cfg = compose_config(
        [f"model.formulation={formulation}", f"model.calibrated={calibrated}", "runs=3", "duration=4.0"]
    )
    data = build_quadrotor_data(data_settings(cfg))
    m = data.model
    k = 300  # mid-flight
    x = data.truth[:, k] + 0.05 * np.random.default_rng(0).standard_normal(data.truth[:, k].shape)
    u = m.filter_input(data.inputs[:, k], data.companion_truth[:, k])
    assert m.F_analytic(x, u) is not None and m.H_analytic(x, u) is not None
    check_model(m, x, u)  # both against central differences, and the batch restricted to each run


@pytest.mark.slow
def test_filter_model_predicts_the_truth_one_step_ahead():
    """f applied to the true state with the true rotor speeds lands close to the next true
    state: the Euler discretisation error is far below the default process noise."""
    cfg = compose_config(["runs=2", "duration=6.0", "sensor.encoder.lines=0", "model.formulation=augmented"])
    data = build_quadrotor_data(data_settings(cfg))
    m = data.model
    worst = 0.0
    for k in range(200, 500):
        u = m.filter_input(data.inputs[:, k], data.companion_truth[:, k])
        pred = m.f(data.truth[:, k][:, None], u)[:, 0]
        worst = max(worst, float(np.abs(pred - data.truth[:, k + 1]).max()))
    assert worst < 0.2 * cfg.model.process_noise.angle_rate


# --- sensors -------------------------------------------------------------------------------


def test_scale_factor_and_cross_coupling_are_applied_as_drawn():
    spec = TriadSpec(scale_factor=0.01, cross_coupling=5e-3, white_noise=0.0)
    rngs = [np.random.default_rng(i) for i in range(4)]
    err = draw_triad_errors(spec, rngs)
    y = np.zeros((4, 1, 3))
    y[:, 0, 0] = 2.0
    out = err.apply(y)
    np.testing.assert_allclose(out[:, 0, 0], 2.0 * err.matrix[:, 0, 0])
    np.testing.assert_allclose(out[:, 0, 1:], 2.0 * err.matrix[:, 1:, 0])


def test_asymmetry_acts_with_the_sign_of_the_input():
    spec = TriadSpec(asymmetry=0.01)
    err = draw_triad_errors(spec, [np.random.default_rng(1)])
    y = np.array([[[1.0, -1.0, 0.5]]])
    out = err.apply(y)
    a = err.asymmetry[0]
    # scale factor 1 + a for positive inputs, 1 − a for negative ones
    np.testing.assert_allclose(out[0, 0], [1 + a[0], -(1 - a[1]), 0.5 * (1 + a[2])])


def test_drawn_errors_have_the_specified_spread():
    """Over 4000 runs the sample std of each drawn error is within 5 % of the spec (the
    standard error of a sample std with n = 4000 is about 1.1 %)."""
    spec = TriadSpec(scale_factor=0.01, asymmetry=0.003, cross_coupling=5e-3, bias=0.2)
    err = draw_triad_errors(spec, [np.random.default_rng(i) for i in range(4000)])
    assert abs(np.diagonal(err.matrix, axis1=1, axis2=2).std() / 0.01 - 1) < 0.05
    off = err.matrix[:, ~np.eye(3, dtype=bool)]
    assert abs(off.std() / 5e-3 - 1) < 0.05
    assert abs(err.asymmetry.std() / 0.003 - 1) < 0.05
    assert abs(err.bias.std() / 0.2 - 1) < 0.05


def test_noise_variances_follow_the_discretisation():
    """White noise σ_d = σ_c/√T; random-walk increments σ_bc √T."""
    T = 0.01
    spec = TriadSpec(white_noise=4e-3)
    rngs = [np.random.default_rng(i) for i in range(20)]
    out = measure_triad(spec, draw_triad_errors(spec, rngs), np.zeros((20, 5001, 3)), T, rngs)
    assert abs(out.std() / (4e-3 / np.sqrt(T)) - 1) < 0.02
    walk = TriadSpec(bias_random_walk=3e-3)
    out = measure_triad(walk, draw_triad_errors(walk, rngs), np.zeros((20, 5001, 3)), T, rngs)
    assert abs(np.diff(out, axis=1).std() / (3e-3 * np.sqrt(T)) - 1) < 0.02


def test_error_scale_multiplies_every_term():
    spec = TriadSpec(0.01, 0.003, 5e-3, 0.2, 3e-3, 4e-3)
    scaled = spec.scaled(2.5)
    for name in TriadSpec.__dataclass_fields__:
        assert getattr(scaled, name) == pytest.approx(2.5 * getattr(spec, name))


def test_encoder_quantisation():
    rngs = [np.random.default_rng(0)]
    speeds = np.linspace(200, 250, 101)[None, :, None] * np.ones((1, 1, 4))
    out = measure_rotor_speeds(speeds, 256, 0.0, 0.01, rngs)
    q = encoder_resolution(256, 0.01)
    assert q == pytest.approx(2.454, abs=1e-3)
    np.testing.assert_allclose(out / q, np.round(out / q), atol=1e-9)
    assert np.abs(out - speeds).max() <= q / 2 + 1e-12


def test_streams_are_per_run_and_independent_of_the_number_of_runs():
    a = run_streams(7, 3)["gyro_noise"][2].standard_normal(5)
    b = run_streams(7, 10)["gyro_noise"][2].standard_normal(5)
    np.testing.assert_array_equal(a, b)


# --- controller ----------------------------------------------------------------------------

GAINS = BacksteppingGains()


def fly(name: str, duration: float = 20.0):
    scenario = builtin_scenario_classes()[name]()
    truth = simulate_truth(P, BacksteppingController(P, GAINS), scenario, np.zeros((1, 3)), duration, 0.01, 10)
    refs = [scenario.reference(t) for t in truth.time]
    return truth, refs


@pytest.mark.slow
def test_controller_holds_hover():
    truth, refs = fly("hover", 10.0)
    late = truth.time > 5.0
    pos = truth.state[0, late, 0:3]
    assert np.abs(pos - [0.0, 0.0, 1.0]).max() < 0.01
    assert np.abs(truth.state[0, :, 2] - [r.position[2] for r in refs]).max() < 0.02


@pytest.mark.slow
def test_controller_tracks_figure8_within_half_a_metre():
    truth, refs = fly("figure8")
    ref = np.array([r.position for r in refs])
    err = np.linalg.norm(truth.state[0, :, 0:3] - ref, axis=-1)
    assert err.max() < 0.5
    assert np.sqrt(np.mean(err[truth.time > 8.0] ** 2)) < 0.3


@pytest.mark.slow
def test_controller_tracks_attitude_steps():
    truth, refs = fly("attitude_steps")
    ref = np.array([r.attitude for r in refs])
    err = np.rad2deg(np.abs(truth.state[0, :, 6:9] - ref))
    assert err[:, :2].max() < 5.0  # roll and pitch, including the 0.5 s transitions
    assert err[:, 2].max() < 10.0  # yaw has little control authority (d ≪ l b)
    settled = np.ones_like(truth.time, dtype=bool)
    for start, _, _ in builtin_scenario_classes()["attitude_steps"]().steps:
        settled &= ~((truth.time >= start) & (truth.time < start + 1.5))
    assert err[settled].max() < 1.0
    assert np.abs(truth.state[0, truth.time > 3, 2] - 1.0).max() < 0.1


def test_params_from_config_match_defaults():
    cfg = compose_config([])
    assert quadrotor_params(data_settings(cfg).model) == QuadrotorParams()
