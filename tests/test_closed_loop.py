"""The estimator in the control loop (the controller flies on its estimate): the plant flown on
truth reproduces the open-loop truth bit for bit, every estimator flying its own truth sees the
same draws, a diverging estimator crashes only its own vehicle, and the step-response metrics
match a second-order system's analytic values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf
from scipy.optimize import brentq

from helpers import compose_config
from quadest.app.job import run_job
from quadest.app.settings import data_settings
from quadest.closed_loop.control_metrics import StepEvent, step_events, step_response
from quadest.closed_loop.feedback import StateSensorFeedback, estimate_to_controller_state
from quadest.closed_loop.loops import controlled_models
from quadest.closed_loop.quadrotor import QuadrotorLoop
from quadest.closed_loop.report import control_report
from quadest.config.closed_loop import validate_loop
from quadest.errors import ConfigError
from quadest.estimators.base import Estimator
from quadest.estimators.registry import build_estimator
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.quadrotor_data import build_quadrotor_data, fly_scenario

# Arrays of the pre-change code (commit e1ca917, before the closed loop existed: its
# models/quadrotor_data.py and quadrotor/simulate.py loaded from `git show`), runs=2, duration=1.0:
# the truth flown per scenario (default config), and build_quadrotor_data's arrays with
# model.formulation=augmented and sensor.encoder.noise_std=0.5.
REFERENCE = Path(__file__).parent / "data" / "open_loop_truth_reference.npz"
EPS = np.finfo(float).eps

# How far a stored array may move: its truth is N = TRUTH_STEPS chained RK4 steps (100 samples
# of 10 substeps), element-wise arithmetic whose sin and cos another numpy or libm may round an
# ulp differently. Re-rounding the state after every step by up to 8 ulps moved every array by
# at most 0.63 eps * N * max|array| (measured; 1 ulp: 0.12), so ROUND_OFF = 4 leaves a margin
# of 6. A truth stepped with 9 or 11 substeps instead of 10 moves the arrays by
# up to 170 and 105 of that unit, a flipped sign of the rotor gyroscopic or yaw-drag term by
# 1e7, another seed by 1e9: all well outside.
ROUND_OFF = 4.0
TRUTH_STEPS = 1000


def assert_near(got: np.ndarray, ref: np.ndarray, steps: int, what: str) -> None:
    """``|got - ref| <= ROUND_OFF * eps * steps * max|ref|``: the round-off of ``steps`` chained
    floating-point steps, relative to the array's largest value (its columns are coupled)."""
    atol = ROUND_OFF * EPS * steps * np.abs(ref).max()
    np.testing.assert_allclose(got, ref, rtol=0.0, atol=atol, err_msg=what)


def _cfg(*overrides: str):
    return compose_config(["runs=2", "duration=1.0", *overrides])


def _estimator(cfg, label: str, model) -> Estimator:
    return build_estimator(label, OmegaConf.to_container(cfg.estimator[label], resolve=True), model)


def test_the_open_loop_data_are_the_pre_change_ones():
    """Exact where no rounding can differ: P0 (products of config values), the encoder readings
    (whole quanta; a rounding change flips one only within ~1e-12 of a half quantum) and sample 0
    (the seed-drawn start at rest). x0 is the exact start plus L0 w (a Cholesky factor and an
    n-term product: n steps of round-off); the rest is the flown truth."""
    data = build_quadrotor_data(data_settings(_cfg("model.formulation=augmented", "sensor.encoder.noise_std=0.5")))
    with np.load(REFERENCE) as ref:
        for key in ("P0", "inputs"):
            assert np.array_equal(getattr(data, key), ref[f"open_data/{key}"]), key
        for key in ("truth", "companion_truth"):
            assert np.array_equal(getattr(data, key)[:, 0], ref[f"open_data/{key}"][:, 0]), f"{key} at sample 0"
        assert_near(data.x0, ref["open_data/x0"], data.x0.shape[-1], "x0")
        for key in ("truth", "companion_truth", "measurements"):
            assert_near(getattr(data, key), ref[f"open_data/{key}"], TRUTH_STEPS, key)


@pytest.mark.parametrize("scenario", ["figure8", "attitude_steps"])
@pytest.mark.slow
def test_truth_loop_reproduces_the_open_loop_truth(scenario):
    """Close to the stored pre-change truth (see ROUND_OFF), exact at the seed-drawn start; and
    bit for bit the open loop's truth and data flown today."""
    cfg = _cfg(f"scenario={scenario}", "loop=truth")
    flight, data = QuadrotorLoop.from_settings(data_settings(cfg)).fly_shared("truth")
    with np.load(REFERENCE) as ref:
        assert np.array_equal(flight.truth.state[:, 0], ref[f"{scenario}/state"][:, 0])
        for key in ("state", "specific_force", "command"):
            assert_near(getattr(flight.truth, key), ref[f"{scenario}/{key}"], TRUTH_STEPS, key)
    _, _, today = fly_scenario(data_settings(cfg), run_streams(int(cfg.seed), int(cfg.runs)))
    assert np.array_equal(flight.truth.state, today.state)
    open_loop = build_quadrotor_data(data_settings(cfg))  # what the estimators see is the open loop's too
    for key in ("truth", "companion_truth", "inputs", "measurements", "x0", "P0"):
        assert np.array_equal(getattr(data, key), getattr(open_loop, key)), key
    assert not flight.crashed.any()


class Spy(Estimator):
    """Delegates to ``inner`` and records every primary measurement it is given."""

    def __init__(self, inner: Estimator) -> None:
        super().__init__(inner.model)
        self.inner, self.capabilities, self.seen = inner, inner.capabilities, []

    def initialize(self, x0, P0):
        self.inner.initialize(x0, P0)

    @property
    def failed(self):
        return self.inner.failed

    @property
    def failure_reasons(self):
        return self.inner.failure_reasons

    def predict(self, u):
        self.inner.predict(u)

    def update(self, z, u, sensor=None):
        self.seen.append(z.copy())
        self.inner.update(z, u, sensor)

    @property
    def mean(self):
        return self.inner.mean

    @property
    def covariance(self):
        return self.inner.covariance

    @property
    def sqrt_covariance(self):
        return self.inner.sqrt_covariance

    def innovation(self):
        return self.inner.innovation()


@pytest.mark.slow
def test_every_estimator_sees_the_same_draws_and_one_filter_flies_one_truth():
    # Encoders without quantisation: with 256 lines a round-off difference between two filters
    # flips an encoder count now and then, and the loop amplifies it (docs/closed-loop.md).
    cfg = _cfg("loop=estimate", "duration=2.0", "sensor.encoder.lines=0")
    loop = QuadrotorLoop.from_settings(data_settings(cfg))
    model = loop.filter_model()
    flown, noise = {}, {}
    for label in ("ekf", "ukf", "srukf"):
        spy = Spy(_estimator(cfg, label, model))
        result, flight, data = loop.fly_estimator(label, spy, 50.0, 1)
        assert not flight.crashed.any() and not result.diverged.any()
        assert np.array_equal(result.truth, data.truth[:1])  # the result carries its own truth
        flown[label] = flight.truth.state
        z = np.stack(spy.seen, axis=1)  # samples 1..K
        states = flight.truth.state[:, 1:]
        clean_acc = loop.draws.accel_errors.apply(flight.truth.specific_force[:, 1:])
        clean_gyro = loop.draws.gyro_errors.apply(states[..., 9:12])
        noise[label] = np.concatenate([z[..., :3] - clean_acc, z[..., 3:] - clean_gyro], axis=-1)
    draws = np.concatenate([loop.draws.accel_noise, loop.draws.gyro_noise], axis=-1)[:, 1:]
    for label, realised in noise.items():
        np.testing.assert_allclose(realised, draws, rtol=0, atol=1e-12, err_msg=label)
    assert not np.allclose(flown["ekf"], flown["ukf"], rtol=0, atol=1e-6)  # different filters fly differently
    np.testing.assert_allclose(flown["ukf"], flown["srukf"], rtol=0, atol=1e-8)


def test_the_draws_are_the_open_loops_and_the_state_sensor_has_its_own_stream():
    cfg = _cfg("loop=measured", "sensor.encoder.lines=0", "sensor.encoder.noise_std=0.5")
    loop = QuadrotorLoop.from_settings(data_settings(cfg))
    flight, _ = loop.fly_shared("truth")
    data = build_quadrotor_data(data_settings(cfg))
    clean = np.concatenate(
        [
            loop.draws.accel_errors.apply(flight.truth.specific_force),
            loop.draws.gyro_errors.apply(flight.truth.state[..., 9:12]),
        ],
        axis=-1,
    )
    # open loop: (errors + drift) + white noise; the draws: drift + white noise (round-off apart)
    np.testing.assert_allclose(
        data.measurements - clean,
        np.concatenate([loop.draws.accel_noise, loop.draws.gyro_noise], -1),
        atol=1e-12,
        rtol=0,
    )
    # speed + noise, less the speed: exact to the rounding of sums below 512 rad/s
    noise = data.inputs - flight.truth.state[..., 12:16]
    np.testing.assert_allclose(noise, loop.draws.encoder_noise, rtol=0, atol=2 * np.spacing(512.0))
    plant = loop.plant()
    seen = StateSensorFeedback(loop.state_std).state(plant)
    seeds = run_seed_sequences(int(cfg.seed), int(cfg.runs))["state_sensor"]
    expected = np.stack([np.random.default_rng(s).standard_normal((101, 12))[0] for s in seeds])
    np.testing.assert_array_equal(seen[:, :12] - plant.state[:, :12], loop.state_std * expected)
    assert loop.state_std[6:9] == pytest.approx(np.deg2rad(2.0), rel=1e-5)
    assert loop.state_std[9:12] == pytest.approx(np.deg2rad(5.0), rel=1e-5)


class Diverging(Spy):
    """A filter whose roll-rate estimate of run 1 walks away from step 20 on (1 rad/s per step), or
    turns NaN with ``nan=True``."""

    def __init__(self, inner: Estimator, nan: bool) -> None:
        super().__init__(inner)
        self.nan, self.k = nan, 0

    def update(self, z, u, sensor=None):
        super().update(z, u, sensor)
        self.k += 1

    @property
    def mean(self):
        out = self.inner.mean.copy()
        if self.k >= 20:
            out[1, 3] = np.nan if self.nan else out[1, 3] + (self.k - 19) * 1.0
        return out


@pytest.mark.parametrize(("nan", "reason"), [(False, "attitude beyond max_tilt"), (True, "non-finite command")])
def test_a_diverging_estimator_crashes_its_own_vehicle_and_the_others_fly_on(nan, reason):
    cfg = _cfg("loop=estimate", "scenario=attitude_steps")
    loop = QuadrotorLoop.from_settings(data_settings(cfg))
    model = loop.filter_model()
    bad, bad_flight, _ = loop.fly_estimator("bad", Diverging(_estimator(cfg, "ekf", model), nan), 1e9, 0)
    good, good_flight, _ = loop.fly_estimator("ekf", _estimator(cfg, "ekf", model), 1e9, 0)
    assert bad_flight.crash_step[0] == -1 and bad_flight.crash_step[1] >= 20
    assert bad_flight.crash_reasons[1].startswith(reason)
    assert bad.diverged.tolist() == [False, True]
    assert nan or "vehicle crashed" in bad.reasons[1]  # a NaN estimate is flagged by the runner first
    assert np.isfinite(bad_flight.truth.state).all()  # the crashed vehicle is frozen, not NaN
    K = len(loop.references) - 1
    assert bad.steps[0] == K and bad.steps[1] <= bad_flight.crash_step[1]
    assert not good_flight.crashed.any() and not good.diverged.any() and (good.steps == K).all()
    metrics = loop.metrics(bad_flight)
    assert np.isnan(metrics["tracking_rmse_roll"][1]) and np.isfinite(metrics["tracking_rmse_roll"][0])


def _second_order(t, zeta, wn):
    """Unit step response of ``wn² / (s² + 2 ζ wn s + wn²)``, 0 < ζ < 1."""
    wd = wn * np.sqrt(1 - zeta**2)
    return 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t))


def _settling_time(zeta, wn, band):
    """Exact ``band`` settling time: the last exit of the band lies between the last peak outside
    it, ``t = kπ/wd`` with ``|y − 1| = exp(−ζ wn t)``, and the next peak."""
    wd = wn * np.sqrt(1 - zeta**2)
    k = int(np.floor(-np.log(band) / (zeta * wn) * wd / np.pi))
    sign = (-1) ** (k + 1)  # odd peaks overshoot
    return brentq(lambda t: _second_order(t, zeta, wn) - 1 - sign * band, k * np.pi / wd, (k + 1) * np.pi / wd)


@pytest.mark.parametrize(("zeta", "wn"), [(0.4, 6.0), (0.7, 10.0), (0.15, 3.0)])
def test_step_metrics_match_a_second_order_response(zeta, wn):
    dt, t0, amplitude, offset = 1e-3, 2.0, 0.07, 0.005
    time = np.arange(0, 20.0, dt)
    tau = np.clip(time - t0, 0, None)
    y0 = -0.02
    late = (time >= 19.5).astype(float)  # a 1 % shift over the last half second: 0.5 % over the last second
    unit = _second_order(tau, zeta, wn)
    y = y0 + amplitude * np.stack([unit, (1 + offset) * unit, unit + 0.01 * late])
    event = StepEvent(t0, 0, y0, y0 + amplitude, 20.0)
    got = step_response(time, y, event, band=0.02, steady_window=1.0)
    overshoot = 100 * np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2))
    # sampling: the sampled peak lies within max|y''| dt²/2 <= wn² dt²/2 (relative) of the true one
    assert got["overshoot_pct"][0] == pytest.approx(overshoot, abs=100 * wn**2 * dt**2)
    # the first sample at or after the exact settling time
    assert 0 <= got["settling_time_s"][0] - _settling_time(zeta, wn, 0.02) <= dt + 1e-9
    # the transient left in the last second is below exp(-ζ wn 17 s) of the step; round-off of the
    # mean of 1000 normalised samples stays below 1000 ε (in %: 1e-10)
    tol = 100 * np.exp(-zeta * wn * 17) * (1 + offset) + 1e-10
    assert got["steady_state_error_pct"][0] == pytest.approx(0.0, abs=tol)
    assert got["steady_state_error_pct"][1] == pytest.approx(100 * offset, abs=tol)
    assert got["steady_state_error_pct"][2] == pytest.approx(0.5, abs=tol + 100 * 0.01 * dt)


def test_rise_time_matches_hand_computed_responses():
    """10-90 % rise time: a first-order lag 1 - exp(-t/tau) crosses level l at -tau ln(1 - l), so its
    rise time is tau ln 9 exactly; a ramp t / T sampled coarsely (the levels between samples) rises in
    0.8 T, which linear interpolation between samples gives to round-off; a response that never
    reaches 90 % has none."""
    tau, T, t0, dt = 0.3, 1.0, 2.0, 1e-3
    time = np.arange(0, 6.0, dt)
    lag = 1 - np.exp(-np.clip(time - t0, 0, None) / tau)
    event = StepEvent(t0, 0, 0.0, 1.0, 6.0)
    got = step_response(time, np.stack([lag, 0.85 * lag]), event, band=0.02, steady_window=1.0)
    # linear interpolation errs by at most max|r''| dt^2 / 8 in r, i.e. dt^2 / (8 tau) e^(dt/tau) in time
    assert got["rise_time_s"][0] == pytest.approx(tau * np.log(9), abs=dt**2 / tau)
    assert np.isnan(got["rise_time_s"][1])
    coarse = np.arange(0, 6.0, 0.07)
    ramp = np.clip((coarse - t0) / T, 0, 1)
    got = step_response(coarse, ramp[None, :], event, band=0.02, steady_window=1.0)
    assert got["rise_time_s"][0] == pytest.approx(0.8 * T, abs=1e-12)


def test_step_events_follow_the_scenario():
    events = step_events([[5.0, 0, 4.0], [10.0, 1, 4.0], [30.0, 0, 0.0], [40.0, 1, 0.0]], 35.0)
    assert [(e.time, e.axis, e.end_time) for e in events] == [(5.0, 0, 30.0), (10.0, 1, 35.0), (30.0, 0, 35.0)]
    assert events[0].start_value == 0.0 and events[0].target == pytest.approx(np.deg2rad(4.0))
    assert events[2].start_value == pytest.approx(np.deg2rad(4.0)) and events[2].target == 0.0


@pytest.mark.parametrize("formulation", ["thesis", "augmented"])
def test_a_perfect_estimate_hands_the_controller_the_truth(formulation):
    cfg = _cfg("loop=truth", f"model.formulation={formulation}")
    flight, data = QuadrotorLoop.from_settings(data_settings(cfg)).fly_shared("truth")
    truth = flight.truth.state[:, 60]
    fed = estimate_to_controller_state(data.model, data.truth[:, 60], data.companion_truth[:, 60], truth[:, 12:16])
    np.testing.assert_allclose(fed, truth, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("formulation", ["thesis", "augmented"])
@pytest.mark.parametrize("loop", ["truth", "measured", "estimate"])
@pytest.mark.integration
@pytest.mark.slow
def test_every_loop_flies_every_quadrotor_formulation(tmp_path, formulation, loop):
    cfg = _cfg(f"loop={loop}", f"model.formulation={formulation}", "duration=0.5", "scenario=attitude_steps",
               "estimator=[ekf]", "workers=1", "output.figures=false", "output.saved_runs=1")  # fmt: skip
    summary = run_job(cfg, tmp_path)
    assert summary["labels"]["loop"] == loop
    assert summary["crashes"] and not any(summary["crashes"].values())
    assert summary["estimators"]["ekf"]["diverged"] == 0
    assert (summary["pcrlb_note"] is None) == (loop != "estimate")
    for name in ("control_metrics.csv", "control_summary.csv", "control_table.md", "metrics.csv", "timeseries.npz"):
        assert (tmp_path / name).is_file()


@pytest.mark.parametrize(
    ("overrides", "key", "allowed"),
    [
        (["loop=closed"], "loop", "one of ['open', 'truth', 'measured', 'estimate']"),
        (["model=ungm", "loop=estimate"], "loop", "'open' only for model=ungm"),
        (["model=seed001_rates", "loop=truth"], "loop", "'open' only for model=seed001_rates"),
        (["loop=measured", "closed_loop.state_sensor.rate=-1.0"], "closed_loop.state_sensor.rate", ">= 0"),
        (["loop=truth", "closed_loop.settling_band=1.5"], "closed_loop.settling_band", "(0, 1)"),
    ],
)
@pytest.mark.integration
def test_bad_loop_settings_fail_in_one_line_before_any_work(tmp_path, overrides, key, allowed):
    cfg = _cfg(*overrides)
    settings = data_settings(cfg)
    with pytest.raises(ConfigError) as err:
        validate_loop(settings.loop, settings.model.name, settings.closed_loop, controlled_models())
    assert err.value.key == key and allowed in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ConfigError):
        run_job(cfg, tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.integration
@pytest.mark.slow
def test_the_sweep_report_puts_the_loop_modes_side_by_side(tmp_path):
    for job, loop in enumerate(("measured", "estimate")):
        cfg = _cfg(f"loop={loop}", "duration=0.5", "scenario=attitude_steps", "scenario.steps=[[0.2,0.0,4.0]]",
                   "estimator=[ekf]", "workers=1", "output.saved_runs=1", "output.figures=false")  # fmt: skip
        run_job(cfg, tmp_path / str(job))
    table = control_report(tmp_path)
    text = table.read_text()
    assert "measured: measured" in text and "estimate: ekf" in text and "overshoot_pct[roll 0->4 deg at 0.2 s]" in text
    summary = pd.read_csv(tmp_path / "closed_loop" / "control_summary.csv")
    per_run = pd.concat([pd.read_csv(tmp_path / str(j) / "control_metrics.csv") for j in (0, 1)])
    row = summary[(summary["flown_by"] == "ekf") & (summary["metric"] == "control_effort")].iloc[0]
    values = per_run[(per_run["flown_by"] == "ekf") & (per_run["metric"] == "control_effort")]["value"]
    assert row["mean"] == pytest.approx(values.mean()) and row["n"] == 2
    assert (tmp_path / "closed_loop" / "tracking.png").is_file()
