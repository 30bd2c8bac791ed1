"""Backstepping controller that flies the truth (thesis ch. 3 form; Bouabdallah & Siegwart 2005).

For every channel ``ẍ = f(x) + β U`` with tracking error ``z1 = x_d − x`` and
``z2 = ẋ − ẋ_d − α1 z1``, the control

    β U = z1 − f(x) + ẍ_d − α1 (z2 + α1 z1) − α2 z2

gives ``V̇ = −α1 z1² − α2 z2²`` for ``V = (z1² + z2²)/2``. The translational channels produce a
desired thrust-acceleration vector, from which the thrust U1 and (in position mode) the roll and
pitch references follow; the three Euler-angle channels produce the torques, using the full
Euler-angle dynamics of thesis eq. 5.31 as ``f`` and ``β = W⁻¹ I⁻¹``. Rotor speeds follow by
inverting the mixer, clipped to the motor limits.

The controller reads whatever 16-state it is handed. In the open loop
(:func:`~quadest.quadrotor.simulate.simulate_truth`) and with ``loop: truth`` that is the true
state: an idealisation that matches neither arm of seed 003, whose baseline ("EKF out") feeds the
controller the noisy measured states, and whose other arm feeds it the EKF's estimate. Those two
are ``loop: measured`` and ``loop: estimate`` (:mod:`quadest.closed_loop`, docs/closed-loop.md);
with ``model=seed003_attitude`` only roll, pitch and the body rates are replaced (by the
measurement or the estimate) and everything else is the truth (:mod:`quadest.closed_loop.seed003`).
Seed 003's gains k1 = 6, k2 = 4 are the attitude pair (α1, α2) = (6, 4) of this law, whose error
dynamics ``s² + (α1 + α2) s + 1 + α1 α2`` then have a double pole at −5 rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.quadrotor.dynamics import body_angular_accel, rotor_inputs
from quadest.quadrotor.kinematics import (
    matvec,
    rate_matrix,
    rate_matrix_inv,
    rate_matrix_inv_partials,
    rotation,
    wrap_angle,
)
from quadest.quadrotor.params import QuadrotorParams
from quadest.quadrotor.scenarios import Reference


@dataclass(frozen=True)
class BacksteppingGains:
    """(α1, α2) pairs per channel group, and the tilt limit of the position loop (rad)."""

    position: tuple[float, float] = (1.5, 2.0)
    altitude: tuple[float, float] = (2.0, 3.0)
    attitude: tuple[float, float] = (10.0, 10.0)
    yaw: tuple[float, float] = (5.0, 5.0)
    max_tilt: float = 0.6


def _backstep(
    z1: np.ndarray,
    z_dot: np.ndarray,
    ref_dot: np.ndarray,
    ref_ddot: np.ndarray,
    drift: np.ndarray,
    a1: np.ndarray,
    a2: np.ndarray,
) -> np.ndarray:
    """``β U`` of the backstepping law for tracking error ``z1`` and rate ``z_dot``."""
    z2 = z_dot - ref_dot - a1 * z1
    return z1 - drift + ref_ddot - a1 * (z2 + a1 * z1) - a2 * z2


class BacksteppingController:
    """Maps the true 16-state (B, 16) and a :class:`Reference` to rotor-speed commands (B, 4)."""

    def __init__(self, params: QuadrotorParams, gains: BacksteppingGains) -> None:
        self.params = params
        self.gains = gains
        self._mixer_inv = np.linalg.inv(params.mixer)
        g = gains
        self._pos_a1 = np.array([g.position[0], g.position[0], g.altitude[0]])
        self._pos_a2 = np.array([g.position[1], g.position[1], g.altitude[1]])
        self._att_a1 = np.array([g.attitude[0], g.attitude[0], g.yaw[0]])
        self._att_a2 = np.array([g.attitude[1], g.attitude[1], g.yaw[1]])

    def command(self, state: np.ndarray, ref: Reference) -> np.ndarray:
        p = self.params
        pos, vel = state[:, 0:3], state[:, 3:6]
        angles, omega, speeds = state[:, 6:9], state[:, 9:12], state[:, 12:16]

        # Translational channels: desired thrust acceleration vector t = R e_z U1 / m.
        drift = -p.kt * vel / p.mass - np.array([0.0, 0.0, p.gravity])
        t = _backstep(ref.position - pos, vel, ref.velocity, ref.acceleration, drift, self._pos_a1, self._pos_a2)
        t[:, 2] = np.maximum(t[:, 2], 0.1 * p.gravity)

        desired = np.broadcast_to(ref.attitude, angles.shape).copy()
        if not ref.attitude_mode:
            psi = desired[:, 2]
            tx = np.cos(psi) * t[:, 0] + np.sin(psi) * t[:, 1]
            ty = -np.sin(psi) * t[:, 0] + np.cos(psi) * t[:, 1]
            norm = np.linalg.norm(t, axis=-1)
            desired[:, 0] = np.arcsin(np.clip(-ty / norm, -1.0, 1.0))
            desired[:, 1] = np.arctan2(tx, t[:, 2])
            desired[:, :2] = np.clip(desired[:, :2], -self.gains.max_tilt, self.gains.max_tilt)
            thrust = p.mass * np.einsum("bi,bi->b", t, rotation(angles)[:, :, 2])
        else:
            thrust = p.mass * t[:, 2] / (np.cos(angles[:, 0]) * np.cos(angles[:, 1]))

        # Attitude channels: Θ̈ = Ẇ⁻¹ ω + W⁻¹ I⁻¹ (drift torques + τ).
        rates = matvec(rate_matrix_inv(angles), omega)
        _, omega_r = rotor_inputs(p, speeds)
        free = body_angular_accel(p, omega, np.zeros_like(omega), omega_r)
        d_phi, d_theta = rate_matrix_inv_partials(angles)
        w_inv_dot = d_phi * rates[:, 0, None, None] + d_theta * rates[:, 1, None, None]
        drift_att = matvec(w_inv_dot, omega) + matvec(rate_matrix_inv(angles), free)
        err = desired - angles
        err[:, 2] = wrap_angle(err[:, 2])
        accel_cmd = _backstep(err, rates, ref.attitude_rate, ref.attitude_accel, drift_att, self._att_a1, self._att_a2)
        torques = p.inertia_vec * matvec(rate_matrix(angles), accel_cmd)

        U = np.concatenate([np.maximum(thrust, 0.0)[:, None], torques], axis=-1)
        squares = matvec(self._mixer_inv, U)
        squares = np.clip(squares, p.rotor_speed_min**2, p.rotor_speed_max**2)
        return np.sqrt(squares)
