"""The quadrotor as a plant: truth, MIMU and encoders stepped one sample at a time under a command.

:func:`~quadest.quadrotor.simulate.simulate_truth` flies a whole scenario with a controller that
reads the true state. In a closed loop the command at sample k depends on what the controller is
fed (truth, noisy states, an estimate), so the truth must advance one sample at a time. Every
random number the sensors need is drawn beforehand (:class:`PlantDraws`, once per run from the
run's streams), so that every estimator flying its own truth sees the same noise draws (common
random numbers), and the plant itself is deterministic given its command.

The truth is advanced exactly as :func:`~quadest.quadrotor.simulate.simulate_truth` does it (RK4
at ``sample_period / substeps`` with the command held over the sample), so a plant fed the true
state reproduces it bit for bit. Runs whose ``active`` flag is cleared (a crash) stay frozen at
their last state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.quadrotor.dynamics import rk4_step
from quadest.quadrotor.params import QuadrotorParams
from quadest.quadrotor.simulate import truth_specific_force
from quadest.sensors.encoders import measure_rotor_speeds
from quadest.sensors.mimu import TriadErrors


@dataclass(frozen=True)
class PlantDraws:
    """Every random number of a batch of B runs over K+1 samples, drawn once per run.

    Attributes:
        start: (B, 3) initial positions.
        accel_errors, gyro_errors: the deterministic triad errors (S, S±, M, b0) of each run.
        accel_noise, gyro_noise: (B, K+1, 3) random-walk drift plus white noise of each triad.
        encoder_noise: (B, K+1, 4) white noise of the encoders, before quantisation.
        state_noise: (B, K+1, 12) standard normals of the state sensor (position, velocity,
            Euler angles, body rates), scaled by its standard deviations where used.
    """

    start: np.ndarray
    accel_errors: TriadErrors
    gyro_errors: TriadErrors
    accel_noise: np.ndarray
    gyro_noise: np.ndarray
    encoder_noise: np.ndarray
    state_noise: np.ndarray


class QuadrotorPlant:
    """A batch of quadrotors with their MIMU and encoders, advanced one sample per :meth:`step`.

    Args:
        params: physical parameters of the truth.
        draws: the runs' random numbers.
        sample_period: T (s); the command is held over each sample.
        substeps: RK4 steps per sample.
        encoder_lines: encoder lines per revolution (0: no quantisation).
    """

    def __init__(
        self, params: QuadrotorParams, draws: PlantDraws, sample_period: float, substeps: int, encoder_lines: int
    ) -> None:
        self.params, self.draws = params, draws
        self.sample_period, self.substeps, self.encoder_lines = sample_period, substeps, encoder_lines
        self.k = 0
        self.state = np.zeros((draws.start.shape[0], 16))
        self.state[:, 0:3] = draws.start
        self.state[:, 12:16] = params.hover_speed

    def step(self, command: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Advance the active runs one sample under ``command`` (B, 4); returns the new truth (B, 16)."""
        h = self.sample_period / self.substeps
        state = self.state
        with np.errstate(invalid="ignore", over="ignore"):
            for _ in range(self.substeps):
                state = rk4_step(self.params, state, command, h)
        self.state = np.where(active[:, None], state, self.state)
        self.k += 1
        return self.state

    def encoders(self) -> np.ndarray:
        """The encoders' rotor speeds now (B, 4): true speeds plus this sample's noise, quantised."""
        noisy = self.state[:, None, 12:16] + self.draws.encoder_noise[:, self.k, None]
        return measure_rotor_speeds(noisy, self.encoder_lines, 0.0, self.sample_period, [])[:, 0]

    def mimu(self) -> np.ndarray:
        """The MIMU now (B, 6): accelerometer then gyro, deterministic errors plus this sample's
        drift and white noise."""
        d, k = self.draws, self.k
        acc = d.accel_errors.apply(truth_specific_force(self.params, self.state)) + d.accel_noise[:, k]
        gyro = d.gyro_errors.apply(self.state[:, 9:12]) + d.gyro_noise[:, k]
        return np.concatenate([acc, gyro], axis=-1)
