"""What the controller reads in each loop mode, as a 16-state laid out like the truth.

- ``truth``: the true state (today's flight; the estimators only watch);
- ``measured``: the true state plus the state sensor's white noise on position, velocity, Euler
  angles and body rates (seed 003's levels: σ = 5 °/s on the rates, 2° on the angles, which in
  seed 003 are its airflow angles α, β), rotor speeds from the encoders;
- ``estimate``: the estimator's own estimate; what the filter state lacks comes from its
  companion integration (thesis §5.3.1: positions, and for the thesis formulation the Euler
  angles, integrated from the estimated rates), rotor speeds from the encoders.
"""

from __future__ import annotations

import numpy as np

from quadest.models.quadrotor import QuadrotorFilterModel
from quadest.quadrotor.dynamics import body_rates
from quadest.quadrotor.plant import QuadrotorPlant
from quadest.runner import EstimatorTracker


class TruthFeedback:
    """The controller reads the true state."""

    def state(self, plant: QuadrotorPlant) -> np.ndarray:
        return plant.state

    def observe(self, plant: QuadrotorPlant, crashes: dict[int, str]) -> None:
        """Nothing to do: the truth needs no update."""


class StateSensorFeedback:
    """The controller reads the true state through the state sensor: ``std`` (12,) one-sigma
    white noise on (position, velocity, Euler angles, body rates), from the plant's draws."""

    def __init__(self, std: np.ndarray) -> None:
        self.std = std

    def state(self, plant: QuadrotorPlant) -> np.ndarray:
        out = plant.state.copy()
        out[:, 0:12] += self.std * plant.draws.state_noise[:, plant.k]
        out[:, 12:16] = plant.encoders()
        return out

    def observe(self, plant: QuadrotorPlant, crashes: dict[int, str]) -> None:
        """Nothing to do: each sample's noise is drawn beforehand."""


def estimate_to_controller_state(
    model: QuadrotorFilterModel, mean: np.ndarray, companion: np.ndarray, speeds: np.ndarray
) -> np.ndarray:
    """The 16-state the controller reads from a quadrotor filter's estimate (B, n), its companion
    values (B, nc) and the encoders' rotor speeds (B, 4): position from the companion, velocity and
    Euler-angle rates from the estimate, Euler angles from the estimate (``augmented``) or the
    companion (``thesis``), body rates ``ω = W(Θ) Θ̇``."""
    out = np.empty((mean.shape[0], 16))
    angles = companion[:, 3:6] if model.thesis else mean[:, 3:6]
    out[:, 0:3] = companion[:, 0:3]
    out[:, 3:6] = mean[:, 0:3]
    out[:, 6:9] = angles
    out[:, 9:12] = body_rates(angles, mean[:, 3:6] if model.thesis else mean[:, 6:9])
    out[:, 12:16] = speeds
    return out


class EstimateFeedback:
    """The controller reads the estimator's estimate; the estimator steps with every new sample of
    the plant (MIMU and encoders) and is scored against that plant's truth.

    A crashed run is flagged in the tracker at the sample after its crash, so that it stops
    counting in the estimation metrics too.
    """

    def __init__(self, tracker: EstimatorTracker, plant: QuadrotorPlant) -> None:
        self.tracker, self.model = tracker, tracker.model
        self.u_prev = plant.encoders()

    def state(self, plant: QuadrotorPlant) -> np.ndarray:
        return estimate_to_controller_state(self.model, self.tracker.est.mean, self.tracker.companion, self.u_prev)

    def observe(self, plant: QuadrotorPlant, crashes: dict[int, str]) -> None:
        k, u_now = plant.k, plant.encoders()
        ended = np.isin(np.arange(plant.state.shape[0]), list(crashes))
        self.tracker.flag(ended, k, lambda i: f"vehicle crashed: {crashes[i]}")
        x_true = self.model.truth_to_state(plant.state)
        self.tracker.step(k, self.u_prev, u_now, plant.mimu(), x_true, self.model.truth_to_companion(plant.state))
        self.u_prev = u_now
