"""Seed 003's 5-state filter in the loop (model=seed003_attitude): the EKF is the hand-written
linear Kalman filter with Φ = I + F·Ts and H = I, the controller reads exactly φ, θ, p, q, r from
the estimate (or the measurement) and everything else from the truth, the arms share their draws,
and the transient metrics match a second-order step response."""

from __future__ import annotations

from functools import partial

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf

from helpers import compose_config
from quadest.app.job import run_job
from quadest.app.settings import data_settings
from quadest.app.validate import validate_model
from quadest.closed_loop.control_metrics import StepEvent, step_response
from quadest.closed_loop.loops import closed_loop_for, controlled_models
from quadest.closed_loop.seed003 import Seed003Loop, controller_state
from quadest.closed_loop.seed003_report import paired_rows, seed003_report
from quadest.config.closed_loop import validate_loop
from quadest.errors import ConfigError
from quadest.estimators.registry import build_estimator
from quadest.models.seed003_attitude import SLOTS, measure_states, sensor_std, state_sensor_normals
from quadest.montecarlo.streams import run_streams
from quadest.simulation.quadrotor_data import draw_plant
from quadest.simulation.registry import build_data
from test_closed_loop import _settling_time


def _cfg(*overrides: str):
    return compose_config(["experiment=seed003_closed_loop", "hydra.mode=RUN", "runs=3", "duration=6.0", *overrides])


def _ekf(cfg, model):
    return build_estimator("ekf", OmegaConf.to_container(cfg.estimator["ekf"], resolve=True), model)


def _derivative(params, x, *, u):
    """ẋ of (φ, θ, p, q, r), written out from the OS4 equations (Bouabdallah 2007) independently
    of the model: Euler-angle kinematics and Euler's equation with rotor gyroscope and drag."""
    phi, theta, p, q, r = x
    w2 = u**2
    b, d, arm = params.thrust_factor, params.drag_factor, params.arm
    tau = np.array([arm * b * (w2[3] - w2[1]), arm * b * (w2[2] - w2[0]), d * (w2[0] - w2[1] + w2[2] - w2[3])])
    wr = u[0] - u[1] + u[2] - u[3]
    ix, iy, iz = params.inertia
    jr, kr = params.rotor_inertia, params.rotational_drag
    return np.array([
        p + np.sin(phi) * np.tan(theta) * q + np.cos(phi) * np.tan(theta) * r,
        np.cos(phi) * q - np.sin(phi) * r,
        ((iy - iz) * q * r - jr * q * wr + tau[0] - kr[0] * p) / ix,
        ((iz - ix) * p * r + jr * p * wr + tau[1] - kr[1] * q) / iy,
        ((ix - iy) * p * q + tau[2] - kr[2] * r) / iz,
    ])  # fmt: skip


def _central_jacobian(fun, x, h):
    return np.stack([(fun(x + h * e) - fun(x - h * e)) / (2 * h) for e in np.eye(x.size)], axis=-1)


def test_the_ekf_is_the_linear_kalman_filter_with_phi_i_plus_f_ts_and_h_identity():
    cfg = _cfg("loop=open", "runs=2", "duration=1.0", "scenario.steps=[[0.3,0.0,4.0],[0.5,1.0,4.0]]")
    data = build_data(data_settings(cfg))
    model, T = data.model, float(cfg.sample_period)
    est = _ekf(cfg, model)
    B, K1 = data.truth.shape[:2]
    est.initialize(data.x0.copy(), np.broadcast_to(data.P0, (B, 5, 5)).copy())
    x, P = data.x0.copy(), np.broadcast_to(data.P0, (B, 5, 5)).copy()
    Q, R, h = np.asarray(cfg.model.Q), np.asarray(cfg.model.R), 1e-5
    for k in range(1, K1):
        u = data.inputs[:, k - 1]
        for i in range(B):
            fx = partial(_derivative, model.params, u=u[i])
            Phi = np.eye(5) + T * _central_jacobian(fx, x[i], h)  # seed 003 eq. 11
            x_pred, P_pred = x[i] + T * fx(x[i]), Phi @ P[i] @ Phi.T + np.diag(Q)
            K = P_pred @ np.linalg.inv(P_pred + np.diag(R))  # H = I
            x[i] = x_pred + K @ (data.measurements[i, k] - x_pred)
            P[i] = (np.eye(5) - K) @ P_pred
        est.predict(u)
        est.update(data.measurements[:, k], data.inputs[:, k])
        # The central difference errs by h² |ẋ'''|/6 plus round-off ε|ẋ|/h (about 1e-10 relative);
        # 1e-7 leaves three orders of magnitude for its growth through the recursion.
        np.testing.assert_allclose(est.mean, x, rtol=1e-7, atol=1e-7 * np.abs(x).max())
        np.testing.assert_allclose(est.covariance, P, rtol=1e-7, atol=1e-7 * np.abs(P).max())


@pytest.mark.slow
def test_the_analytic_jacobian_is_the_derivative_of_the_continuous_dynamics():
    cfg = _cfg("loop=open")
    data = build_data(data_settings(cfg))
    model = data.model
    rng = np.random.default_rng(3)
    x = np.array([0.3, -0.2, 0.5, -0.4, 0.2]) + 0.1 * rng.standard_normal((3, 5))
    u = data.inputs[:, 50] + rng.uniform(-20, 20, (3, 4))
    J = model.continuous_jacobian(x, u)
    for i in range(3):
        ref = _central_jacobian(partial(_derivative, model.params, u=u[i]), x[i], 1e-6)
        np.testing.assert_allclose(J[i], ref, rtol=1e-6, atol=1e-6 * np.abs(ref).max())
    np.testing.assert_array_equal(model.F_analytic(x, u), np.eye(5) + model.dt * J)


class _FixedEstimate:
    def __init__(self, mean):
        self.mean = mean


class _Tracker:
    def __init__(self, model, mean):
        self.model, self.est = model, _FixedEstimate(mean)


def test_the_controller_reads_exactly_the_five_states_from_the_estimate_and_the_rest_from_the_truth():
    loop = Seed003Loop.from_settings(data_settings(_cfg("loop=estimate")))
    plant = loop.plant()
    plant.step(np.full((3, 4), loop.controller.params.hover_speed + 5.0), np.ones(3, dtype=bool))
    plant.state[:, 3:6] += 0.3  # a moving vehicle: every slot differs from the estimate's
    estimate = np.arange(15.0).reshape(3, 5) / 100.0
    fed = loop.estimate_feedback(_Tracker(loop.filter_model(), estimate), plant).state(plant)
    others = np.setdiff1d(np.arange(16), SLOTS)
    np.testing.assert_array_equal(fed[:, SLOTS], estimate)
    np.testing.assert_array_equal(fed[:, others], plant.state[:, others])
    measured = loop.shared_feedback("measured").state(plant)
    z = plant.state[:, SLOTS] + sensor_std(loop.settings.closed_loop) * plant.draws.state_noise[:, plant.k][:, SLOTS]
    np.testing.assert_array_equal(measured[:, SLOTS], z)
    np.testing.assert_array_equal(measured[:, others], plant.state[:, others])


def test_every_command_in_flight_is_the_controllers_on_the_truth_with_the_estimated_five():
    cfg = _cfg("loop=estimate", "duration=2.0")
    loop = Seed003Loop.from_settings(data_settings(cfg))
    result, flight, _ = loop.fly_estimator("ekf", _ekf(cfg, loop.filter_model()), 50.0, 3)
    for k in (0, 1, 57, 199):
        fed = controller_state(flight.truth.state[:, k], result.saved["estimate"][:, k])
        np.testing.assert_array_equal(flight.truth.command[:, k], loop.controller.command(fed, loop.references[k]))


@pytest.mark.slow
def test_the_arms_share_their_draws_and_the_ekf_sees_what_the_noisy_controller_read():
    cfg = _cfg("duration=1.0")
    loop = Seed003Loop.from_settings(data_settings(cfg))
    streams = run_streams(int(cfg.seed), int(cfg.runs))
    K1 = len(loop.references)
    np.testing.assert_array_equal(loop.draws.state_noise, state_sensor_normals(streams, K1))
    np.testing.assert_array_equal(
        loop.draws.state_noise, draw_plant(data_settings(cfg), run_streams(int(cfg.seed), 3), loop.flown).state_noise
    )
    out_flight, out_data = loop.fly_shared("measured")
    std = sensor_std(data_settings(cfg).closed_loop)
    np.testing.assert_array_equal(
        out_data.measurements, measure_states(out_flight.truth.state, loop.draws.state_noise, std)
    )
    _, in_flight, in_data = loop.fly_estimator("ekf", _ekf(cfg, loop.filter_model()), 50.0, 0)
    # sample 0: EKF in reads x0 = z_0, EKF out reads z_0: the same command from the same draw
    np.testing.assert_array_equal(in_flight.truth.command[:, 0], out_flight.truth.command[:, 0])
    np.testing.assert_array_equal(in_data.x0, out_data.measurements[:, 0])
    _, truth_data = loop.fly_shared("truth")
    open_data = build_data(data_settings(_cfg("loop=open", "duration=1.0")))
    np.testing.assert_array_equal(truth_data.measurements, open_data.measurements)
    np.testing.assert_array_equal(truth_data.truth, open_data.truth)


def _second_order(t, zeta, wn):
    wd = wn * np.sqrt(1 - zeta**2)
    return 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t))


@pytest.mark.parametrize(("zeta", "wn"), [(0.4, 6.0), (0.6, 8.0)])
def test_the_overshoot_is_the_transients_peak_and_a_late_bump_is_the_peak_error(zeta, wn):
    dt, t0, window = 1e-3, 1.0, 2.0
    time = np.arange(0, 20.0, dt)
    unit = _second_order(np.clip(time - t0, 0, None), zeta, wn)
    bump = 0.3 * np.exp(-(((time - 12.0) / 0.05) ** 2))  # a 30 % noise peak 11 s after the step
    event = StepEvent(t0, 0, 0.0, 0.07, 20.0)
    got = step_response(time, 0.07 * (unit + bump)[None], event, 0.02, 1.0, transient_window=window)
    whole = step_response(time, 0.07 * (unit + bump)[None], event, 0.02, 1.0)
    overshoot = 100 * np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2))
    # the sampled peak lies within wn² dt²/2 (relative) of the true one
    assert got["overshoot_pct"][0] == pytest.approx(overshoot, abs=100 * wn**2 * dt**2)
    assert whole["overshoot_pct"][0] > 29.0  # without the window the late bump counts as overshoot
    # after the window: the bump's sampled peak (the transient left is below exp(-ζ wn 2 s) of the step)
    assert got["peak_error_pct"][0] == pytest.approx(30.0, abs=100 * np.exp(-zeta * wn * window) + 1e-6)
    assert "peak_error_pct" not in whole
    # settling within the window: the first sample at or after the exact settling time; without
    # the window the bump is a late exit from the band
    assert 0 <= got["settling_time_s"][0] - _settling_time(zeta, wn, 0.02) <= dt + 1e-9
    assert whole["settling_time_s"][0] > 11.0


def test_the_paired_rows_difference_the_same_runs_of_both_arms():
    rows = []
    for loop, values in (("estimate", [1.0, 2.0, np.nan, 4.0]), ("measured", [3.0, 5.0, 1.0, 4.5])):
        rows += [{"loop": loop, "flown_by": loop, "run": i, "metric": "m", "value": v} for i, v in enumerate(values)]
    out = paired_rows(pd.DataFrame(rows)).set_index("arm")
    diff = out.loc["in_minus_out"]
    assert diff["n"] == 3 and diff["mean"] == pytest.approx(np.mean([-2.0, -3.0, -0.5]))
    assert out.loc["ekf_out", "n"] == 4 and diff["ci_low"] < diff["mean"] < diff["ci_high"]


@pytest.mark.parametrize(
    ("override", "key", "allowed"),
    [
        ("model.Q=[1e-8,1e-8,1e-4]", "model.Q", "five variances"),
        ("model.R=[0.0012,0.0,0.0076,0.0076,0.0076]", "model.R[1]", "> 0"),
        ("closed_loop.transient_window=-1.0", "closed_loop.transient_window", "> 0 seconds, or null"),
    ],
)
def test_bad_seed003_settings_fail_in_one_line(override, key, allowed):
    settings = data_settings(_cfg("loop=estimate", override))
    with pytest.raises(ConfigError) as err:
        if key.startswith("model"):
            validate_model(settings)
        else:
            validate_loop(settings.loop, settings.model.name, settings.closed_loop, controlled_models())
    assert err.value.key == key and allowed in str(err.value) and "\n" not in str(err.value)


def test_the_job_builds_the_seed003_loop_for_its_model():
    assert type(closed_loop_for(data_settings(_cfg("loop=truth")))) is Seed003Loop


@pytest.mark.integration
@pytest.mark.slow
def test_the_report_pairs_the_arms_runs_for_control_and_estimation_metrics(tmp_path):
    for job, loop in enumerate(("measured", "estimate")):
        cfg = _cfg(f"loop={loop}", "runs=3", "duration=2.5", "scenario.steps=[[0.2,0.0,4.0]]", "output.saved_runs=1")
        run_job(cfg, tmp_path / str(job))
    rows = pd.read_csv(seed003_report(tmp_path)).fillna({"step": ""}).set_index(["metric", "step", "arm"])
    arms = {
        loop: pd.read_csv(tmp_path / str(j) / "control_metrics.csv") for j, loop in enumerate(("measured", "estimate"))
    }
    rate = {k: v[v["metric"] == "command_rate"].set_index("run")["value"] for k, v in arms.items()}
    assert rows.loc[("command_rate", "", "in_minus_out"), "mean"] == pytest.approx(
        (rate["estimate"] - rate["measured"]).mean()
    )
    rmse = {
        j: pd.read_csv(tmp_path / str(j) / "metrics.csv").query("state == 'p'").set_index("run")["rmse"] for j in (0, 1)
    }
    assert rows.loc[("estimate_rmse", "p", "ekf_out"), "mean"] == pytest.approx(rmse[0].mean())
    assert rows.loc[("estimate_rmse", "p", "in_minus_out"), "mean"] == pytest.approx((rmse[1] - rmse[0]).mean())
    assert (tmp_path / "seed003" / "tracking.png").is_file() and (tmp_path / "seed003" / "model_error.csv").is_file()
