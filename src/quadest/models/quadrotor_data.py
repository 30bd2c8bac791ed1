"""Monte Carlo data of ``model=quadrotor``: fly the scenario, measure it with the MIMU and the
encoders, and bind the filter model to the runs' assumed sensor errors."""

from __future__ import annotations

import numpy as np

from quadest.models.quadrotor import QuadrotorFilterModel
from quadest.models.quadrotor_config import (
    controller_gains,
    group_diagonal,
    measurement_covariance,
    quadrotor_params,
    scenario,
    triad_spec,
)
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.initial import draw_initial_estimates, initial_covariance
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.quadrotor.controller import BacksteppingController
from quadest.quadrotor.simulate import simulate_truth
from quadest.sensors.encoders import encoder_resolution, measure_rotor_speeds
from quadest.sensors.mimu import TriadErrors, draw_triad_errors, measure_triad


def fly_scenario(cfg, streams: dict):
    """``(params, scenario, truth)``: the quadrotor of ``cfg.model`` flown by the backstepping
    controller through ``cfg.scenario`` once per run, each run starting at a horizontal position
    drawn from its ``"start"`` stream."""
    mcfg, T = cfg.model, float(cfg.sample_period)
    params = quadrotor_params(mcfg)
    flown = scenario(cfg.scenario)
    start = np.zeros((len(streams["start"]), 3))
    for i, rng in enumerate(streams["start"]):
        start[i, :2] = flown.initial_position_std * rng.standard_normal(2)
    controller = BacksteppingController(params, controller_gains(mcfg.controller))
    truth = simulate_truth(params, controller, flown, start, float(cfg.duration), T, int(mcfg.truth_substeps))
    return params, flown, truth


def build_quadrotor_data(cfg) -> MonteCarloData:
    """Fly the scenario for ``cfg.runs`` runs and record what the filters see."""
    mcfg, scfg = cfg.model, cfg.sensor
    runs, T, seed = int(cfg.runs), float(cfg.sample_period), int(cfg.seed)
    streams = run_streams(seed, runs)
    params, flown, truth = fly_scenario(cfg, streams)

    scale = float(scfg.error_scale)
    accel, gyro = triad_spec(scfg.accel, scale), triad_spec(scfg.gyro, scale)
    accel_errors = draw_triad_errors(accel, streams["accel_errors"])
    gyro_errors = draw_triad_errors(gyro, streams["gyro_errors"])
    z_acc = measure_triad(accel, accel_errors, truth.specific_force, T, streams["accel_noise"])
    z_gyro = measure_triad(gyro, gyro_errors, truth.state[..., 9:12], T, streams["gyro_noise"])
    u = measure_rotor_speeds(
        truth.state[..., 12:16], int(scfg.encoder.lines), float(scfg.encoder.noise_std), T, streams["encoder"]
    )

    assumed_acc, assumed_gyro = (
        (accel_errors, gyro_errors) if mcfg.calibrated else (TriadErrors.nominal(runs), TriadErrors.nominal(runs))
    )
    state_names = QuadrotorFilterModel.formulation_state_names(mcfg.formulation)
    Q = np.diag(group_diagonal(state_names, mcfg.process_noise) ** 2)
    R = measurement_covariance(accel, gyro, T, float(cfg.duration), float(mcfg.measurement_noise_inflation))
    model = QuadrotorFilterModel(params, mcfg.formulation, T, Q, R, assumed_acc, assumed_gyro)

    x_true = model.truth_to_state(truth.state)
    P0 = initial_covariance(group_diagonal(state_names, mcfg.initial_std), float(mcfg.initial_std.correlation))
    companion_truth = model.truth_to_companion(truth.state)
    labels = {
        "model": mcfg.name, "formulation": mcfg.formulation, "calibrated": bool(mcfg.calibrated),
        "sensor": scfg.name, "error_scale": scale, "scenario": flown.name,
        "encoder_resolution": encoder_resolution(int(scfg.encoder.lines), T) if scfg.encoder.lines else 0.0,
    }  # fmt: skip
    return MonteCarloData(
        model=model,
        time=truth.time,
        truth=x_true,
        companion_truth=companion_truth,
        inputs=u,
        measurements=np.concatenate([z_acc, z_gyro], axis=-1),
        x0=draw_initial_estimates(x_true[:, 0], P0, streams["initial"]),
        P0=P0,
        companion0=companion_truth[:, 0].copy(),
        estimator_seeds=run_seed_sequences(seed, runs)["estimator"],
        labels=labels,
    )
