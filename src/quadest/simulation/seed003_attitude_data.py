"""Monte Carlo data of ``model=seed003_attitude`` (:mod:`quadest.models.seed003_attitude`): a
16-state flight measured by the state sensor, the five states filtered."""

from __future__ import annotations

import numpy as np

from quadest.config.settings import DataSettings
from quadest.models.schemas import Seed003AttitudeModelConf
from quadest.models.seed003_attitude import (
    ROTORS,
    measure_states,
    seed003_filter_model,
    sensor_std,
    state_sensor_normals,
    validate_seed003_attitude,
)
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.quadrotor_data import fly_scenario
from quadest.simulation.spec import ModelSpec


def seed003_data(settings: DataSettings, truth_state: np.ndarray, normals: np.ndarray, labels: dict) -> MonteCarloData:
    """The data of a flight ``truth_state`` (B, K+1, 16): the five states measured with the state
    sensor's noise from ``normals`` (B, K+1, 12), rotor speeds of the truth as input, and every run
    started at its first measurement with ``P0 = R``."""
    runs, K1 = truth_state.shape[:2]
    model = seed003_filter_model(settings.model, settings.sample_period, runs)
    z = measure_states(truth_state, normals, sensor_std(settings.closed_loop))
    return MonteCarloData(
        model, np.arange(K1) * float(settings.sample_period), model.truth_to_state(truth_state),
        np.zeros((runs, K1, 0)), truth_state[..., ROTORS], z, z[:, 0].copy(), model.R.copy(), np.zeros((runs, 0)),
        run_seed_sequences(int(settings.seed), runs, settings.first_run)["estimator"], labels,
    )  # fmt: skip


def seed003_labels(settings: DataSettings, scenario_name: str) -> dict:
    """The descriptive columns of a seed 003 job's metrics table."""
    return {
        "model": settings.model.name, "formulation": settings.model.name, "calibrated": True, "sensor": "state_sensor",
        "error_scale": np.nan, "scenario": scenario_name, "encoder_resolution": np.nan,
    }  # fmt: skip


def build_seed003_attitude_data(settings: DataSettings) -> MonteCarloData:
    """Open loop: fly the scenario on the truth (the controller reads the true state) and measure
    the five states with the state sensor."""
    streams = run_streams(int(settings.seed), int(settings.runs), settings.first_run)
    _params, flown, truth = fly_scenario(settings, streams)
    normals = state_sensor_normals(streams, truth.state.shape[1])
    return seed003_data(settings, truth.state, normals, seed003_labels(settings, flown.name))


MODEL = ModelSpec(
    "seed003_attitude",
    Seed003AttitudeModelConf,
    build_seed003_attitude_data,
    lambda _: 5,
    validate_seed003_attitude,
    uses_quadrotor_groups=True,
)
