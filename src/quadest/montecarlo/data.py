"""The Monte Carlo data of one job: what every estimator sees, run by run."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.models.base import FilterModel
from quadest.sensors.record import SensorRecord


@dataclass
class MonteCarloData:
    """Everything the runner needs for a batch of B runs over K+1 samples.

    Attributes:
        model: the filter model, bound to the batch.
        time: (K+1,) sample times.
        truth: (B, K+1, n) true filter state.
        companion_truth: (B, K+1, nc) true companion values (see :class:`FilterModel`).
        inputs: (B, K+1, nu_measured) measured inputs (before companions are appended).
        measurements: (B, K+1, m).
        x0: (B, n) initial estimates, drawn from N(truth[:, 0], P0).
        P0: (n, n) initial covariance.
        companion0: (B, nc) initial companion values the filters start from.
        estimator_seeds: B seed sequences, run ``i``'s ``"estimator"`` stream (see
            :mod:`quadest.montecarlo.streams`): the randomness an estimator may draw, apart from
            the truth's and the sensors'.
        labels: descriptive columns for the metrics table.
        sensors: further sensors beside the primary ``measurements``, by name, in update order
            (empty for single-sensor models).
    """

    model: FilterModel
    time: np.ndarray
    truth: np.ndarray
    companion_truth: np.ndarray
    inputs: np.ndarray
    measurements: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    companion0: np.ndarray
    estimator_seeds: list[np.random.SeedSequence]
    labels: dict = field(default_factory=dict)
    sensors: dict[str, SensorRecord] = field(default_factory=dict)


def sample_count(duration: float, sample_period: float) -> int:
    """Number of filter steps K in a run: samples at t_k = k T, k = 0..K."""
    return round(duration / sample_period)
