"""Monte Carlo data of ``model=seed001_rates`` (:mod:`quadest.models.seed001_rates`): the shared
quadrotor flown for its rotor speeds, seed 001's rate model driven by those speeds (with process
noise for ``model.truth=own_model``, without it for ``flown``) as the truth, a white-noise gyro as the
measurement."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from quadest.config.settings import DataSettings
from quadest.models.schemas import Seed001RatesModelConf
from quadest.models.seed001_rates import RATES, ROTORS, RateModel, validate_seed001_rates
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.initial import draw_initial_estimates
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.quadrotor_data import fly_scenario
from quadest.simulation.spec import ModelSpec


def propagate_rates(model: RateModel, start: np.ndarray, rotors: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """The seed's rate model driven by process noise: ``x_0 = start`` (B, 3) and
    ``x_k = f(x_{k−1}, Ω_{k−1}) + noise[:, k]`` for k = 1..K, with ``rotors`` (B, K+1, 4) and
    ``noise`` (B, K+1, 3) (row 0 unused)."""
    rates = np.empty_like(noise)
    rates[:, 0] = start
    for k in range(1, noise.shape[1]):
        rates[:, k] = model.f(rates[:, k - 1][:, None], rotors[:, k - 1])[:, 0] + noise[:, k]
    return rates


def truth_follows_the_filter_model(labels: Mapping[str, Any]) -> bool:
    """The PCRLB of the rate model bounds the filters' MSE only for ``model.truth=own_model``,
    where the rates are driven by the filters' own N(0, Q) process noise; the flown rates have none."""
    return labels.get("truth") == "own_model"


def build_seed001_rates_data(settings: DataSettings) -> MonteCarloData:
    """Fly the scenario for the rotor speeds, drive the rate model from the flown initial rates
    (:func:`propagate_rates`) with N(0, Q·I) process noise from the ``process`` stream
    (``model.truth=own_model``) or with none (``flown``: the flight's rates under the filters'
    Euler step), measure the rates with a white-noise gyro of variance ``R`` from the
    ``measurement`` stream; each run's initial estimate is drawn from N(true rates, P0·I)."""
    m, runs, T, seed = settings.model, int(settings.runs), float(settings.sample_period), int(settings.seed)
    streams = run_streams(seed, runs, settings.first_run)
    params, flown, truth = fly_scenario(settings, streams)
    rotors = truth.state[..., ROTORS]
    K1 = rotors.shape[1]
    model = RateModel(params, T, float(m.Q) * np.eye(3), float(m.R) * np.eye(3), runs)
    if m.truth == "flown":
        process = np.zeros((runs, K1, 3))
    else:
        process = np.stack([rng.standard_normal((K1, 3)) for rng in streams["process"]]) * np.sqrt(float(m.Q))
    rates = propagate_rates(model, truth.state[:, 0, RATES], rotors, process)
    noise = np.stack([rng.standard_normal((K1, 3)) for rng in streams["measurement"]]) * np.sqrt(float(m.R))
    P0 = float(m.P0) * np.eye(3)
    labels = {
        "model": m.name, "formulation": m.name, "calibrated": True, "sensor": "", "error_scale": np.nan,
        "scenario": flown.name, "encoder_resolution": np.nan, "truth": m.truth,
    }  # fmt: skip
    return MonteCarloData(
        model, truth.time, rates, np.zeros((runs, K1, 0)), rotors, rates + noise,
        draw_initial_estimates(rates[:, 0], P0, streams["initial"]), P0, np.zeros((runs, 0)),
        run_seed_sequences(seed, runs, settings.first_run)["estimator"], labels,
    )  # fmt: skip


MODEL = ModelSpec(
    "seed001_rates",
    Seed001RatesModelConf,
    build_seed001_rates_data,
    lambda _: 3,
    validate_seed001_rates,
    uses_quadrotor_groups=True,
    pcrlb_is_bound=truth_follows_the_filter_model,
)
