"""Physical parameters of the OS4 micro-quadrotor (Bouabdallah & Siegwart, ICRA 2005;
Bouabdallah, EPFL thesis 2007, p. 144). The thesis (seed 000) takes its model from its own
chapter 2, whose prototype numbers are not available; this is the reconstruction we use."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class QuadrotorParams:
    """Rigid-body, rotor and motor parameters (SI units)."""

    mass: float = 0.65
    arm: float = 0.23
    inertia: tuple[float, float, float] = (7.5e-3, 7.5e-3, 1.3e-2)
    rotor_inertia: float = 6.0e-5
    thrust_factor: float = 3.13e-5
    drag_factor: float = 7.5e-7
    gravity: float = 9.81
    translational_drag: tuple[float, float, float] = (0.25, 0.25, 0.25)
    rotational_drag: tuple[float, float, float] = (1.0e-3, 1.0e-3, 1.0e-3)
    motor_time_constant: float = 0.05
    rotor_speed_min: float = 24.0
    rotor_speed_max: float = 340.0

    @property
    def hover_speed(self) -> float:
        """Rotor speed at which the four rotors carry the weight, √(mg / 4b) ≈ 225.7 rad/s."""
        return float(np.sqrt(self.mass * self.gravity / (4.0 * self.thrust_factor)))

    @property
    def inertia_vec(self) -> np.ndarray:
        return np.asarray(self.inertia, dtype=float)

    @property
    def kt(self) -> np.ndarray:
        return np.asarray(self.translational_drag, dtype=float)

    @property
    def kr(self) -> np.ndarray:
        return np.asarray(self.rotational_drag, dtype=float)

    @property
    def mixer(self) -> np.ndarray:
        """Matrix M with ``[U1, U2, U3, U4] = M @ Ω²`` (OS4 sign convention)."""
        b, d, l = self.thrust_factor, self.drag_factor, self.arm
        return np.array(
            [
                [b, b, b, b],
                [0.0, -l * b, 0.0, l * b],
                [-l * b, 0.0, l * b, 0.0],
                [d, -d, d, -d],
            ]
        )
