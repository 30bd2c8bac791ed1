"""A batch of plants flown by the controller, fed by a feedback source, one sample at a time.

At sample k the feedback source hands the controller a 16-state (what it believes the vehicle
is doing), the controller commands rotor speeds for the reference at ``t_k``, the crash checks
run on the true state and the command, and the plant advances to sample k+1 under that command
(held over the sample, as in :func:`~quadest.quadrotor.simulate.simulate_truth`); the feedback
source then sees sample k+1 (an estimator predicts and updates with it). A crashed run is
frozen and ends there; the others fly on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from quadest.quadrotor.controller import BacksteppingController
from quadest.quadrotor.plant import QuadrotorPlant
from quadest.quadrotor.scenarios import Reference
from quadest.quadrotor.simulate import TruthTrajectory, truth_specific_force


class Feedback(Protocol):
    """What the controller reads: ``state(plant)`` (B, 16) at the plant's current sample; after
    each plant step, ``observe(plant, crashes)`` sees the new sample and the crashes so far
    (run → reason)."""

    def state(self, plant: QuadrotorPlant) -> np.ndarray: ...

    def observe(self, plant: QuadrotorPlant, crashes: dict[int, str]) -> None: ...


@dataclass(frozen=True)
class CrashLimits:
    """A run crashes when ``|roll|`` or ``|pitch|`` exceeds ``max_tilt`` (rad), when it sinks
    ``ground_depth`` (m) below the take-off plane, or when its command is not finite."""

    max_tilt: float
    ground_depth: float

    def reasons(self, state: np.ndarray, command: np.ndarray) -> list[str]:
        """One reason per run ("" for a run that has not crashed), the first that applies."""
        bad_command = ~np.isfinite(command).all(-1)
        with np.errstate(invalid="ignore"):
            tilted = ~(np.abs(state[:, 6:8]) <= self.max_tilt).all(-1)
            grounded = ~(state[:, 2] >= -self.ground_depth)
        out = []
        for i in range(state.shape[0]):
            if bad_command[i]:
                out.append("non-finite command")
            elif tilted[i]:
                out.append(f"attitude beyond max_tilt={self.max_tilt} rad")
            elif grounded[i]:
                out.append(f"ground contact (z below -{self.ground_depth} m)")
            else:
                out.append("")
        return out


@dataclass
class Flight:
    """The flown batch: the truth and commands of every sample, and which runs crashed when.

    ``crash_step[i]`` is the sample at which run i crashed (−1: it did not); from there on its
    truth is frozen and its commands are NaN.
    """

    truth: TruthTrajectory
    crash_step: np.ndarray
    crash_reasons: dict[int, str] = field(default_factory=dict)

    @property
    def crashed(self) -> np.ndarray:
        return self.crash_step >= 0


@dataclass
class FlightRecord:
    """What a job keeps of a flight: which runs crashed when and why, the control metrics of every
    run (NaN for crashed runs), and the truth and commands of the first runs (as many as the flight
    was recorded with). Small enough to cache with an estimator's result (``loop: estimate``) or
    with the job's data (``truth``, ``measured``)."""

    crash_step: np.ndarray
    crash_reasons: dict[int, str]
    metrics: dict[str, np.ndarray]
    state: np.ndarray
    command: np.ndarray

    @property
    def crashed(self) -> np.ndarray:
        return self.crash_step >= 0


def fly(
    plant: QuadrotorPlant,
    controller: BacksteppingController,
    references: list[Reference],
    feedback: Feedback,
    limits: CrashLimits,
) -> Flight:
    """Fly ``plant`` through ``references`` (one per sample, K+1) with the controller fed by
    ``feedback``; returns the flight, with the specific force of the truth at every sample."""
    B, K1 = plant.state.shape[0], len(references)
    states, commands = np.empty((B, K1, 16)), np.full((B, K1, 4), np.nan)
    crash_step = np.full(B, -1)
    reasons: dict[int, str] = {}
    for k, ref in enumerate(references):
        states[:, k] = plant.state
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            cmd = controller.command(feedback.state(plant), ref)
        alive = crash_step < 0
        for i, why in enumerate(limits.reasons(plant.state, cmd)):
            if why and alive[i]:
                crash_step[i], reasons[i] = k, why
        alive = crash_step < 0
        commands[alive, k] = cmd[alive]
        if k == K1 - 1:
            break
        plant.step(cmd, alive)
        feedback.observe(plant, reasons)
    time = np.arange(K1) * plant.sample_period
    truth = TruthTrajectory(time, states, truth_specific_force(plant.params, states), commands)
    return Flight(truth, crash_step, reasons)
