"""Seed 003's two arms on the quadrotor (``model=seed003_attitude``, docs/closed-loop.md).

Seed 003 (Cao, Liu & Li) compares a backstepping controller fed its five key states from the EKF
("EKF in") with the same controller fed the noisy measurements of those states while the EKF only
watches ("EKF out"); everything else is the same in both. Here the five states are roll, pitch and
the body rates (φ, θ, p, q, r; :mod:`quadest.models.seed003_attitude`), and the controller reads

- ``loop: estimate`` (EKF in): those five from the filter's estimate x̂_{k|k};
- ``loop: measured`` (EKF out): those five from the state sensor's measurement z_k;
- ``loop: truth``: the true state (the reference flight);

and **everything else** (position, velocity, yaw, rotor speeds) from the truth, in every arm. The
state sensor's noise at sample k comes from the plant's draws (the run's ``state_sensor`` stream):
the EKF of every arm and the noisy-state controller read the same z_k, and the arms fly on the same
draws (common random numbers).
"""

from __future__ import annotations

import numpy as np

from quadest.closed_loop.feedback import TruthFeedback
from quadest.closed_loop.quadrotor import QuadrotorLoop
from quadest.models.seed003_attitude import SLOTS, AttitudeRateModel, measure_states, seed003_filter_model, sensor_std
from quadest.montecarlo import MonteCarloData
from quadest.quadrotor.plant import QuadrotorPlant
from quadest.runner import EstimatorTracker
from quadest.simulation.seed003_attitude_data import MODEL as SEED003_MODEL
from quadest.simulation.seed003_attitude_data import seed003_data, seed003_labels


def controller_state(truth: np.ndarray, states: np.ndarray) -> np.ndarray:
    """The 16-state the controller reads: the truth (B, 16) with φ, θ, p, q, r replaced by ``states`` (B, 5)."""
    out = truth.copy()
    out[:, SLOTS] = states
    return out


class MeasuredStatesFeedback:
    """EKF out: the controller reads the five states as the state sensor measures them now."""

    def __init__(self, std: np.ndarray) -> None:
        self.std = std

    def measurement(self, plant: QuadrotorPlant) -> np.ndarray:
        """z_k (B, 5) at the plant's current sample."""
        return measure_states(plant.state, plant.draws.state_noise[:, plant.k], self.std)

    def state(self, plant: QuadrotorPlant) -> np.ndarray:
        return controller_state(plant.state, self.measurement(plant))

    def observe(self, plant: QuadrotorPlant, crashes: dict[int, str]) -> None:
        """Nothing to do: each sample's noise is drawn beforehand."""


class EstimatedStatesFeedback(MeasuredStatesFeedback):
    """EKF in: the controller reads the five states from the filter's estimate x̂_{k|k}. After each
    plant step the filter predicts with the rotor speeds of sample k and updates with z_{k+1}."""

    def __init__(self, tracker: EstimatorTracker, plant: QuadrotorPlant, std: np.ndarray) -> None:
        super().__init__(std)
        self.tracker, self.model = tracker, tracker.model
        self.u_prev = plant.state[:, 12:16].copy()

    def state(self, plant: QuadrotorPlant) -> np.ndarray:
        return controller_state(plant.state, self.tracker.est.mean)

    def observe(self, plant: QuadrotorPlant, crashes: dict[int, str]) -> None:
        k, u_now = plant.k, plant.state[:, 12:16].copy()
        ended = np.isin(np.arange(plant.state.shape[0]), list(crashes))
        self.tracker.flag(ended, k, lambda i: f"vehicle crashed: {crashes[i]}")
        x_true = self.model.truth_to_state(plant.state)
        self.tracker.step(k, self.u_prev, u_now, self.measurement(plant), x_true, x_true[:, :0])
        self.u_prev = u_now


class Seed003Loop(QuadrotorLoop):
    """The closed loop of ``model=seed003_attitude``: :class:`QuadrotorLoop`'s plant, controller,
    references and crash limits, with seed 003's feedback and its 5-state filter."""

    model_name = SEED003_MODEL.name

    def shared_feedback(self, loop: str) -> TruthFeedback | MeasuredStatesFeedback:
        return TruthFeedback() if loop == "truth" else MeasuredStatesFeedback(sensor_std(self.settings.closed_loop))

    def estimate_feedback(self, tracker: EstimatorTracker, plant: QuadrotorPlant) -> EstimatedStatesFeedback:
        return EstimatedStatesFeedback(tracker, plant, sensor_std(self.settings.closed_loop))

    def record(self, flight) -> MonteCarloData:
        return self._flight_data(self.filter_model(), flight.truth.state)

    def filter_model(self) -> AttitudeRateModel:
        s = self.settings
        return seed003_filter_model(s.model, s.sample_period, int(s.runs))

    def _flight_data(self, model: AttitudeRateModel, states: np.ndarray) -> MonteCarloData:
        normals = self.draws.state_noise[:, : states.shape[1]]
        return seed003_data(self.settings, states, normals, seed003_labels(self.settings, self.flown.name))
