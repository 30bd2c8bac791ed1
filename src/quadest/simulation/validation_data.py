"""Monte Carlo data of the validation models (``model=linear``, ``model=ungm``,
:mod:`quadest.models.validation`): the truth is the filter model itself driven by Gaussian process
noise with the model's own Q, the measurements its ``h`` plus noise with its R, one generator per
run from the ``process`` and ``measurement`` streams.
"""

from __future__ import annotations

import numpy as np

from quadest.config.settings import DataSettings
from quadest.models.base import FilterModel
from quadest.models.config_checks import validate_linear, validate_ungm
from quadest.models.schemas import LinearModelConf, UNGMModelConf
from quadest.models.validation import UNGMModel, constant_velocity_model
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.data import sample_count
from quadest.montecarlo.initial import draw_initial_estimates, initial_covariance
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.simulation.spec import ModelSpec


def _simulate(model: FilterModel, x0: np.ndarray, inputs: np.ndarray, streams) -> tuple[np.ndarray, np.ndarray]:
    """Truth and measurements with the model's own Q and R, one generator per run."""
    B, K1 = inputs.shape[:2]
    LQ, LR = np.linalg.cholesky(model.Q), np.linalg.cholesky(model.R)
    process = np.array([rng.standard_normal((K1, model.n)) for rng in streams["process"]]) @ LQ.T
    noise = np.array([rng.standard_normal((K1, model.m)) for rng in streams["measurement"]]) @ LR.T
    x = np.empty((B, K1, model.n))
    x[:, 0] = x0
    for k in range(1, K1):
        x[:, k] = model.f(x[:, k - 1][:, None], inputs[:, k - 1])[:, 0] + process[:, k]
    z = np.stack([model.h(x[:, k][:, None], inputs[:, k])[:, 0] for k in range(K1)], axis=1) + noise
    return x, z


def simulation_labels(settings: DataSettings) -> dict:
    """The metrics-table labels of a model whose data is not a quadrotor flight (no sensor,
    scenario or encoder: those columns stay empty)."""
    return {
        "model": settings.model.name,
        "formulation": settings.model.name,
        "calibrated": True,
        "sensor": "",
        "error_scale": np.nan,
        "scenario": "",
        "encoder_resolution": np.nan,
    }


def data_from_filter_model(
    settings: DataSettings,
    model: FilterModel,
    x0_true: np.ndarray,
    x0_est: np.ndarray,
    P0: np.ndarray,
    inputs: np.ndarray,
) -> MonteCarloData:
    """The Monte Carlo data of a model whose truth *is* its filter model (the validation models, a
    plugin's small model, docs/models.md): ``x_k = f(x_{k−1}, u_{k−1}) + w_k``,
    ``z_k = h(x_k, u_k) + v_k`` with ``w ~ N(0, Q)`` from each run's ``process`` stream and
    ``v ~ N(0, R)`` from its ``measurement`` stream (:mod:`quadest.montecarlo.streams`), so the
    PCRLB of ``model`` is a true bound.

    Args:
        settings: the job config (``runs``, ``seed``, ``sample_period``; labels from ``model.name``).
        model: the filter model bound to ``settings.runs`` runs (``Q`` (n, n), ``R`` (m, m)).
        x0_true: (B, n) true initial states.
        x0_est: (B, n) the filters' initial estimates.
        P0: (n, n) the filters' initial covariance.
        inputs: (B, K+1, nu) the input at every sample (``nu`` may be 0).
    """
    runs, seed = int(settings.runs), int(settings.seed)
    streams = run_streams(seed, runs, settings.first_run)
    x, z = _simulate(model, x0_true, inputs, streams)
    K1 = inputs.shape[1]
    time = np.arange(K1) * float(settings.sample_period)
    empty = np.zeros((runs, K1, 0))
    labels = simulation_labels(settings)
    estimator_seeds = run_seed_sequences(seed, runs, settings.first_run)["estimator"]
    return MonteCarloData(model, time, x, empty, inputs, z, x0_est, P0, np.zeros((runs, 0)), estimator_seeds, labels)


def build_linear_data(settings: DataSettings) -> MonteCarloData:
    """Monte Carlo data of ``model=linear``: the truth starts at ``initial_state``, each run's
    initial estimate is drawn from N(truth, P0)."""
    runs, K = int(settings.runs), sample_count(settings.duration, settings.sample_period)
    model = constant_velocity_model(settings, runs)
    std = np.array(list(settings.model.initial_std))
    P0 = initial_covariance(std, float(settings.model.initial_correlation))
    x0 = np.broadcast_to(np.array(list(settings.model.initial_state), dtype=float), (runs, 4))
    est = draw_initial_estimates(x0, P0, run_streams(int(settings.seed), runs, settings.first_run)["initial"])
    return data_from_filter_model(settings, model, x0, est, P0, np.zeros((runs, K + 1, 0)))


def build_ungm_data(settings: DataSettings) -> MonteCarloData:
    """Monte Carlo data of ``model=ungm``: the truth starts from N(x0_mean, x0_var) (deterministic
    when ``x0_var`` is 0), every filter from (m0, P0)."""
    runs, K = int(settings.runs), sample_count(settings.duration, settings.sample_period)
    m = settings.model
    model = UNGMModel(float(m.Q), float(m.R), float(settings.sample_period), runs)
    x0 = float(m.x0_mean) + np.sqrt(float(m.x0_var)) * np.array(
        [rng.standard_normal(1) for rng in run_streams(int(settings.seed), runs, settings.first_run)["start"]]
    )
    inputs = np.broadcast_to(np.arange(K + 1, dtype=float)[None, :, None], (runs, K + 1, 1)).copy()
    est = np.full((runs, 1), float(m.m0))
    return data_from_filter_model(settings, model, x0, est, np.array([[float(m.P0)]]), inputs)


LINEAR = ModelSpec("linear", LinearModelConf, build_linear_data, lambda _: 4, validate_linear, pcrlb_is_bound=True)
# UNGM's time is its step index (f uses cos(1.2 k)): one step per second; 50 steps as in Gordon, Salmond &
# Smith (1993); errors of 2|x| from the sign ambiguity of x^2/20 are the model's, not a divergence.
UNGM = ModelSpec("ungm", UNGMModelConf, build_ungm_data, lambda _: 1, validate_ungm, pcrlb_is_bound=True,
                 job_defaults={"duration": 50.0, "sample_period": 1.0, "divergence_bound": 1.0e6})  # fmt: skip
