"""Seed 001's second reading of its truth, ``model.truth=flown`` (Li & Liang 2015, §3.1: the truth
is the quadrotor flown by the backstepping controller): the rates of the flight under the filters'
Euler step, with no process noise, while the filters keep their assumed Q. The default,
``own_model``, is tested against its own construction in tests/test_seed001_rates.py."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import compose_config
from quadest.app.settings import data_settings
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.evaluation.pcrlb import pcrlb_caption, pcrlb_is_bound
from quadest.montecarlo.streams import run_streams
from quadest.simulation.quadrotor_data import fly_scenario
from quadest.simulation.registry import build_data

RUNS, DURATION = 3, 3.0  # 150 steps of 20 ms, through the tilt at 2 s
FLOWN = ["experiment=seed001_rates", f"runs={RUNS}", f"duration={DURATION}", "model.truth=flown"]


def flown_data(seed: int):
    cfg = compose_config([*FLOWN, f"seed={seed}"])
    return cfg, build_data(data_settings(cfg))


def test_the_flown_truth_has_no_process_noise():
    """Two seeds give the same true rates (nothing random drives them) but different gyro draws:
    the measurement keeps its noise, the truth has none. The start position, the only other draw,
    does not change the attitude manoeuvre, so every run flies the same rates."""
    (_, a), (_, b) = flown_data(1), flown_data(2)
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_array_equal(a.truth, np.broadcast_to(a.truth[:1], a.truth.shape))
    noise_a, noise_b = a.measurements - a.truth, b.measurements - b.truth
    assert np.all(noise_a != noise_b)


def test_the_flown_truth_is_the_euler_step_of_the_flown_rotor_speeds():
    """The true rates start at the flight's rates and follow ``x_k = x_{k−1} + T ω̇(x_{k−1}, Ω_{k−1})``
    with Ω the rotor speeds of the quadrotor flown by the backstepping controller (recomputed here
    from the scenario) and ω̇ Bouabdallah's Euler equation (OS4: rotor gyroscopic term and
    rotational drag) written out below, not the model's ``f``. Tolerance: the two recursions differ
    only in the order of the floating-point operations, about 1e-16 relative per step, over 150
    steps of a recursion whose Jacobian ``I + T ∂ω̇/∂ω`` has norm close to 1."""
    cfg, data = flown_data(1)
    settings = data_settings(cfg)
    params, _, flight = fly_scenario(settings, run_streams(int(cfg.seed), RUNS, settings.first_run))
    speeds = flight.state[..., 12:16]
    np.testing.assert_array_equal(data.inputs, speeds)
    ix, iy, iz = params.inertia
    kr, jr, b, d, arm = params.kr, params.rotor_inertia, params.thrust_factor, params.drag_factor, params.arm
    T = float(cfg.sample_period)
    expected = np.empty_like(data.truth)
    expected[:, 0] = flight.state[:, 0, 9:12]
    for k in range(1, expected.shape[1]):
        p, q, r = expected[:, k - 1].T
        w1, w2, w3, w4 = speeds[:, k - 1].T
        u2, u3, u4 = arm * b * (w4**2 - w2**2), arm * b * (w3**2 - w1**2), d * (w1**2 - w2**2 + w3**2 - w4**2)
        jw = jr * (w1 - w2 + w3 - w4)
        accel = np.stack(
            [
                ((iy - iz) * q * r - jw * q + u2 - kr[0] * p) / ix,
                ((iz - ix) * p * r + jw * p + u3 - kr[1] * q) / iy,
                ((ix - iy) * p * q + u4 - kr[2] * r) / iz,
            ],
            axis=-1,
        )
        expected[:, k] = expected[:, k - 1] + T * accel
    np.testing.assert_allclose(data.truth, expected, rtol=1e-12, atol=1e-12)
    assert np.abs(data.truth).max() > 0.5  # the manoeuvre turns the vehicle: the check is not on zeros


def test_the_pcrlb_is_called_a_bound_only_where_the_truth_follows_the_filter_model():
    """The flown rates have no process noise, so the filter model's PCRLB (with its Q) is no floor
    for them: the EKF's pooled MSE sits well below it (tests/test_seed001_rates.py holds the
    filters to it on the default truth). The caption under the table and the figure say which."""
    cfg, data = flown_data(1)
    assert not pcrlb_is_bound(cfg.model.name, data.labels)
    assert "not a bound" in pcrlb_caption(cfg.model.name, labels=data.labels)
    default = build_data(data_settings(compose_config(["experiment=seed001_rates", "runs=2", "duration=0.2"])))
    assert pcrlb_is_bound(cfg.model.name, default.labels)
    assert "not a bound" not in pcrlb_caption(cfg.model.name, labels=default.labels)
    assert not pcrlb_is_bound(cfg.model.name)  # a model whose truth is a setting, asked without its data


def test_an_unknown_truth_is_refused_before_any_work():
    """``validate`` runs before any data is built: one line naming the key and the allowed values."""
    with pytest.raises(ConfigError) as err:
        validate(compose_config(["experiment=seed001_rates", "model.truth=flow"]))
    message = str(err.value)
    assert "\n" not in message
    assert "model.truth" in message and "'own_model'" in message and "'flown'" in message
