"""Monte Carlo data of ``model=upf_benchmark`` (:mod:`quadest.models.upf_benchmark`): the truth
driven by Gamma increments, the measurements with Gaussian noise, every run from the known start."""

from __future__ import annotations

import math

import numpy as np

from quadest.config.settings import DataSettings
from quadest.models.schemas import UPFBenchmarkModelConf
from quadest.models.upf_benchmark import UPFBenchmarkModel, validate_upf_benchmark
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.data import sample_count
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.spec import ModelSpec
from quadest.simulation.validation_data import simulation_labels


def build_upf_benchmark_data(settings: DataSettings) -> MonteCarloData:
    """Truth and measurements of ``model=upf_benchmark``: every run starts at ``x0`` (known
    exactly); the Gamma increments come from the ``process`` stream, the measurement noise from
    the ``measurement`` stream of each run; every filter starts from (x0, P0)."""
    runs, seed, K = int(settings.runs), int(settings.seed), sample_count(settings.duration, settings.sample_period)
    m = settings.model
    model = UPFBenchmarkModel(
        float(m.Q), float(m.R), float(m.gamma_shape), float(m.gamma_rate), float(m.switch_time),
        float(settings.sample_period), runs,
    )  # fmt: skip
    streams = run_streams(seed, runs, settings.first_run)
    inputs = np.broadcast_to(np.arange(1.0, K + 2.0)[None, :, None], (runs, K + 1, 1)).copy()
    v = np.stack([model.sample_process_noise(rng, (K + 1,)) for rng in streams["process"]])
    n = np.stack([rng.standard_normal((K + 1, 1)) for rng in streams["measurement"]]) * math.sqrt(float(m.R))
    x = np.empty((runs, K + 1, 1))
    x[:, 0] = float(m.x0)
    for k in range(1, K + 1):
        x[:, k] = model.f(x[:, k - 1][:, None], inputs[:, k - 1])[:, 0] + v[:, k]
    z = np.concatenate([model.h(x[:, k][:, None], inputs[:, k]) for k in range(K + 1)], axis=1) + n
    labels = simulation_labels(settings)
    return MonteCarloData(
        model, np.arange(K + 1) * float(settings.sample_period), x, np.zeros((runs, K + 1, 0)), inputs, z,
        np.full((runs, 1), float(m.x0)), np.array([[float(m.P0)]]), np.zeros((runs, 0)),
        run_seed_sequences(seed, runs, settings.first_run)["estimator"], labels,
    )  # fmt: skip


MODEL = ModelSpec(  # the truth's process noise is Gamma, not the Gaussian the recursion assumes: no bound
    "upf_benchmark",
    UPFBenchmarkModelConf,
    build_upf_benchmark_data,
    lambda _: 1,
    validate_upf_benchmark,
    # van der Merwe et al. (2000), §5.1: 60 time steps t = 1..60 (x_0 and 59 transitions), one per second
    job_defaults={"duration": 59.0, "sample_period": 1.0, "divergence_bound": 1.0e6},
)
