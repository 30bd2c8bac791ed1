"""Monte Carlo data of ``model=book_pendulum`` (:mod:`quadest.models.book_pendulum`): simulated from the
model itself (the truth from ``x0`` with the model's Q, the measurements with its R), or replayed
from a recorded file (``model.recording``, :mod:`quadest.simulation.recorded`), such as the data
file of Särkkä & Svensson's companion code shipped in ``data/sarkka-svensson-2023/``."""

from __future__ import annotations

import numpy as np

from quadest.config.ranges import require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.book_pendulum import BookPendulumModel
from quadest.models.schemas import BookPendulumModelConf
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.data import sample_count
from quadest.simulation.recorded import read_recordings, recorded_data, resolve_recording
from quadest.simulation.spec import ModelSpec
from quadest.simulation.validation_data import data_from_filter_model


def validate_pendulum(settings: DataSettings) -> None:
    """Range checks of ``model=book_pendulum``."""
    m = settings.model
    require_positive("model.g", m.g, "must be > 0 (gravity)")
    require_positive("model.q_c", m.q_c, "must be > 0 (spectral density of the process noise)")
    require_positive("model.R", m.R, "must be > 0 (measurement noise variance)")
    for key in ("m0", "P0", "x0"):
        if len(list(getattr(m, key))) != 2:
            raise ConfigError(f"model.{key}", list(getattr(m, key)), "two values: angle and angular rate")
    for value in m.P0:
        require_positive("model.P0", value, "must be > 0 (initial variances of the filters)")
    if m.recording is not None:
        resolve_recording(m.recording)


def build_pendulum_data(settings: DataSettings) -> MonteCarloData:
    """Every filter starts from ``m0``, ``diag(P0)``; the truth from ``x0``."""
    m, runs = settings.model, int(settings.runs)
    model = BookPendulumModel(float(settings.sample_period), float(m.g), float(m.q_c), float(m.R), runs)
    x0_est = np.broadcast_to(np.array(list(m.m0), dtype=float), (runs, 2)).copy()
    P0 = np.diag(np.array(list(m.P0), dtype=float))
    x0 = np.array(list(m.x0), dtype=float)
    if m.recording is not None:
        recordings = read_recordings(resolve_recording(m.recording))
        return recorded_data(settings, model, recordings, x0_est, P0, initial_truth=x0)
    K = sample_count(settings.duration, settings.sample_period)
    x0_true = np.broadcast_to(x0, (runs, 2)).copy()
    return data_from_filter_model(settings, model, x0_true, x0_est, P0, np.zeros((runs, K + 1, 0)))


BOOK_PENDULUM = ModelSpec(  # the book's Euler step dt = 0.01 and its 500 steps (Särkkä & Svensson 2023, Ex. 5.1)
    "book_pendulum",
    BookPendulumModelConf,
    build_pendulum_data,
    lambda _: 2,
    validate_pendulum,
    pcrlb_is_bound=True,
    job_defaults={"duration": 5.0, "sample_period": 0.01},
)
