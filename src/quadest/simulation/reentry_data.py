"""Monte Carlo data of ``model=reentry`` (:mod:`quadest.models.reentry`), drawn as the EKF/UKF
toolbox manual (Hartikainen, Solin & Särkkä 2011, §3, the reentry demonstration) draws its runs:

    x_0 ~ N(x0, diag(x0_var)),
    x_k = f(x_{k−1}) + L w_{k−1},   w = √(diag(truth_q_c) Δt) e,   e ~ N(0, I₃),
    z_k = h(x_k) + diag(σr, σθ) ε_k,   ε ~ N(0, I₂),   k = 1..K.

The process noise is drawn through the input matrix ``L`` (three standard normals per step, not a
factor of the rank-3 state-space Q), so a zero density leaves its state exactly constant: the truth's
ballistic parameter ``x5`` keeps its initial value. Run ``i`` draws from its own streams
(:func:`quadest.montecarlo.streams.run_streams`: ``start``, ``process``, ``measurement``), so its
data do not depend on the number of runs.
"""

from __future__ import annotations

import numpy as np

from quadest.config.ranges import require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.reentry import NOISE_INPUT, ReentryModel, ReentryModelConf
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.data import sample_count
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.spec import ModelSpec
from quadest.simulation.validation_data import simulation_labels

LENGTHS = {"radar": 2, "q_c": 3, "truth_q_c": 3, "x0": 5, "x0_var": 5, "m0": 5, "P0": 5}


def validate_reentry(settings: DataSettings) -> None:
    """Range checks of ``model=reentry``."""
    m = settings.model
    for key in ("H0", "Gm0", "R0", "sigma_range", "sigma_bearing"):
        require_positive(f"model.{key}", getattr(m, key), "must be > 0")
    for key, size in LENGTHS.items():
        if len(list(getattr(m, key))) != size:
            raise ConfigError(f"model.{key}", list(getattr(m, key)), f"{size} values")
    for key in ("q_c", "truth_q_c", "x0_var"):
        if min(getattr(m, key)) < 0:
            raise ConfigError(f"model.{key}", list(getattr(m, key)), "values >= 0 (variances)")
    for value in m.P0:
        require_positive("model.P0", value, "must be > 0 (initial variances of the filters)")


def reentry_model(settings: DataSettings, q_c: list[float], runs: int) -> ReentryModel:
    """The model of ``settings`` with the noise densities ``q_c``, bound to ``runs`` runs."""
    m = settings.model
    return ReentryModel(float(settings.sample_period), m.beta0, m.H0, m.Gm0, m.R0, tuple(m.radar),
                        m.sigma_range, m.sigma_bearing, np.array(q_c, dtype=float), runs)  # fmt: skip


def simulate_reentry(
    truth_model: ReentryModel, x0: np.ndarray, steps: int, process: np.ndarray, noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Truth (B, K+1, 5) and measurements (B, K+1, 2) from the initial states ``x0`` (B, 5), the
    noise inputs ``process`` (B, K+1, 3) (already scaled; sample k drives the step into k) and the
    measurement noise ``noise`` (B, K+1, 2). The filters update from sample 1 on (the manual's runs
    measure from the first step), so sample 0's measurement is never used."""
    B = x0.shape[0]
    x = np.empty((B, steps + 1, 5))
    x[:, 0] = x0
    for k in range(1, steps + 1):
        x[:, k] = truth_model.f(x[:, k - 1][:, None], None)[:, 0] + process[:, k] @ NOISE_INPUT.T
    return x, truth_model.h(x, None) + noise


def build_reentry_data(settings: DataSettings) -> MonteCarloData:
    """Every filter starts from ``m0``, ``diag(P0)``; the truth as the module docstring draws it."""
    m, runs, seed = settings.model, int(settings.runs), int(settings.seed)
    K = sample_count(settings.duration, settings.sample_period)
    streams = run_streams(seed, runs, settings.first_run)
    x0 = np.array(m.x0, dtype=float) + np.sqrt(np.array(m.x0_var, dtype=float)) * np.array(
        [rng.standard_normal(5) for rng in streams["start"]]
    )
    scale_w = np.sqrt(np.array(m.truth_q_c, dtype=float) * float(settings.sample_period))
    process = np.array([rng.standard_normal((K + 1, 3)) for rng in streams["process"]]) * scale_w
    scale_z = np.array([m.sigma_range, m.sigma_bearing], dtype=float)
    noise = np.array([rng.standard_normal((K + 1, 2)) for rng in streams["measurement"]]) * scale_z
    truth, z = simulate_reentry(reentry_model(settings, m.truth_q_c, runs), x0, K, process, noise)
    model = reentry_model(settings, m.q_c, runs)
    x0_est = np.broadcast_to(np.array(m.m0, dtype=float), (runs, 5)).copy()
    P0 = np.diag(np.array(m.P0, dtype=float))
    time = np.arange(K + 1) * float(settings.sample_period)
    estimator_seeds = run_seed_sequences(seed, runs, settings.first_run)["estimator"]
    return MonteCarloData(model, time, truth, np.zeros((runs, K + 1, 0)), np.zeros((runs, K + 1, 0)), z, x0_est, P0,
                          np.zeros((runs, 0)), estimator_seeds, simulation_labels(settings))  # fmt: skip


REENTRY = ModelSpec("reentry", ReentryModelConf, build_reentry_data, lambda _: 5, validate_reentry)
