"""Truth simulation: the controller flies the quadrotor along a scenario, batched over runs,
reading the true state (the open loop; :mod:`quadest.quadrotor.plant` steps the same truth one
sample at a time for the closed loop)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.quadrotor.controller import BacksteppingController
from quadest.quadrotor.dynamics import rk4_step, rotor_inputs, specific_force
from quadest.quadrotor.params import QuadrotorParams
from quadest.quadrotor.scenarios import Scenario


@dataclass
class TruthTrajectory:
    """Sampled truth of a batch of runs.

    Attributes:
        time: sample times (K+1,), ``t_k = k T``.
        state: 16-state truth at the samples (B, K+1, 16), see ``TRUTH_STATE_NAMES``.
        specific_force: what an ideal accelerometer measures at the samples (B, K+1, 3).
        command: rotor-speed commands held over each sample interval (B, K+1, 4).
    """

    time: np.ndarray
    state: np.ndarray
    specific_force: np.ndarray
    command: np.ndarray


def simulate_truth(
    params: QuadrotorParams,
    controller: BacksteppingController,
    scenario: Scenario,
    initial_position: np.ndarray,
    duration: float,
    sample_period: float,
    substeps: int,
) -> TruthTrajectory:
    """Fly ``scenario`` for every run of the batch.

    The controller runs at the sample period with its command held constant (zero-order hold);
    the rigid body and motors are integrated with RK4 at ``sample_period / substeps``.
    ``initial_position`` (B, 3) sets where each run starts, at rest with the rotors at hover speed.
    """
    B = initial_position.shape[0]
    K = round(duration / sample_period)
    h = sample_period / substeps
    state = np.zeros((B, 16))
    state[:, 0:3] = initial_position
    state[:, 12:16] = params.hover_speed
    states = np.empty((B, K + 1, 16))
    commands = np.empty((B, K + 1, 4))
    time = np.arange(K + 1) * sample_period
    for k in range(K + 1):
        states[:, k] = state
        cmd = controller.command(state, scenario.reference(time[k]))
        commands[:, k] = cmd
        if k == K:
            break
        for _ in range(substeps):
            state = rk4_step(params, state, cmd, h)
    return TruthTrajectory(time, states, truth_specific_force(params, states), commands)


def truth_specific_force(params: QuadrotorParams, state: np.ndarray) -> np.ndarray:
    """What an ideal accelerometer measures (..., 3) for the 16-state truth ``state`` (..., 16)."""
    U, _ = rotor_inputs(params, state[..., 12:16])
    return specific_force(params, state[..., 6:9], state[..., 3:6], U[..., 0])
