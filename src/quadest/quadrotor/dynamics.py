"""Rigid-body and rotor dynamics of the quadrotor (``../shared/reference/quadrotor.md``).

Truth state (16): ``[p (3), v (3), Θ (3), ω (3), Ω (4)]`` — earth-frame position and velocity,
ZYX Euler angles, body rates and the four actual rotor speeds. All functions work over leading
axes and accept complex input (for complex-step derivative checks).

- ``m v̇ = R(Θ) [0, 0, U1]ᵀ − m g e_z − Kt v``
- ``I ω̇ = −ω × Iω − Jr (ω × e_z) Ωr + [U2, U3, U4]ᵀ − Kr ω``
- ``Θ̇ = W(Θ)⁻¹ ω``,  ``ṗ = v``,  ``τm Ω̇ = Ω_cmd − Ω`` (first-order motor lag)
"""

from __future__ import annotations

import numpy as np

from quadest.quadrotor.kinematics import (
    matvec,
    rate_matrix,
    rate_matrix_inv,
    rate_matrix_inv_partials,
    rotation,
)
from quadest.quadrotor.params import QuadrotorParams

TRUTH_STATE_NAMES = (
    "x", "y", "z", "vx", "vy", "vz", "phi", "theta", "psi", "p", "q", "r",
    "rotor1", "rotor2", "rotor3", "rotor4",
)  # fmt: skip


def rotor_inputs(params: QuadrotorParams, speeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Thrust and torques ``U = [U1, U2, U3, U4]`` (..., 4) and the rotor gyroscopic speed
    ``Ωr = Ω1 − Ω2 + Ω3 − Ω4`` (...) from rotor speeds (..., 4)."""
    U = matvec(params.mixer, speeds * speeds)
    omega_r = speeds[..., 0] - speeds[..., 1] + speeds[..., 2] - speeds[..., 3]
    return U, omega_r


def body_angular_accel(
    params: QuadrotorParams, omega: np.ndarray, torques: np.ndarray, omega_r: np.ndarray
) -> np.ndarray:
    """``ω̇`` (..., 3) from Euler's equation with the rotor gyroscopic term and rotational drag.

    ``−ω × Iω = ((Iy − Iz) q r, (Iz − Ix) p r, (Ix − Iy) p q)`` and ``ω × e_z = (q, −p, 0)``.
    """
    ix, iy, iz = params.inertia
    kr = params.kr
    p, q, r = omega[..., 0], omega[..., 1], omega[..., 2]
    jw = params.rotor_inertia * omega_r
    out = np.empty(np.broadcast_shapes(omega.shape, torques.shape), dtype=np.result_type(omega, torques))
    out[..., 0] = ((iy - iz) * q * r - jw * q + torques[..., 0] - kr[0] * p) / ix
    out[..., 1] = ((iz - ix) * p * r + jw * p + torques[..., 1] - kr[1] * q) / iy
    out[..., 2] = ((ix - iy) * p * q + torques[..., 2] - kr[2] * r) / iz
    return out


def translational_accel(
    params: QuadrotorParams, angles: np.ndarray, v: np.ndarray, thrust: np.ndarray
) -> np.ndarray:
    """``v̇`` (..., 3) in the earth frame: thrust along the body z axis, gravity and linear drag."""
    body_z = rotation(angles)[..., :, 2]
    acc = body_z * (thrust / params.mass)[..., None] - params.kt * v / params.mass
    return acc - np.array([0.0, 0.0, params.gravity])


def specific_force(
    params: QuadrotorParams, angles: np.ndarray, v: np.ndarray, thrust: np.ndarray
) -> np.ndarray:
    """What an ideal accelerometer measures: ``f_b = Rᵀ (v̇ + g e_z) = e_z U1/m − Rᵀ Kt v / m``."""
    R = rotation(angles)
    drag_body = np.einsum("...ji,...j->...i", R, params.kt * v) / params.mass
    f = -drag_body
    return f + np.stack(
        [np.zeros_like(thrust), np.zeros_like(thrust), thrust / params.mass], axis=-1
    )


def euler_angle_accel(
    params: QuadrotorParams, angles: np.ndarray, rates: np.ndarray, speeds: np.ndarray
) -> np.ndarray:
    """Euler-angle accelerations ``Θ̈ = (d/dt W⁻¹) ω + W⁻¹ ω̇`` (thesis eq. 5.31).

    ``angles`` and ``rates`` are Θ and Θ̇ (..., 3); ``speeds`` the rotor speeds (..., 4).
    """
    omega = matvec(rate_matrix(angles), rates)
    U, omega_r = rotor_inputs(params, speeds)
    omega_dot = body_angular_accel(params, omega, U[..., 1:], omega_r)
    d_phi, d_theta = rate_matrix_inv_partials(angles)
    w_inv_dot = d_phi * rates[..., 0, None, None] + d_theta * rates[..., 1, None, None]
    return matvec(w_inv_dot, omega) + matvec(rate_matrix_inv(angles), omega_dot)


def truth_derivative(params: QuadrotorParams, state: np.ndarray, speed_cmd: np.ndarray) -> np.ndarray:
    """Time derivative of the 16-state truth (..., 16) under commanded rotor speeds (..., 4).

    Written element by element (the hot loop of the truth simulation); the tests check it
    against the matrix forms :func:`translational_accel`, :func:`body_angular_accel` and
    ``W⁻¹ ω``.
    """
    v, omega, speeds = state[..., 3:6], state[..., 9:12], state[..., 12:16]
    sf, cf = np.sin(state[..., 6]), np.cos(state[..., 6])
    st, ct = np.sin(state[..., 7]), np.cos(state[..., 7])
    sp, cp = np.sin(state[..., 8]), np.cos(state[..., 8])
    U, omega_r = rotor_inputs(params, speeds)
    a = U[..., 0] / params.mass
    kt = params.kt / params.mass
    out = np.empty(np.broadcast_shapes(state.shape, speed_cmd.shape[:-1] + (16,)), dtype=state.dtype)
    out[..., 0:3] = v
    out[..., 3] = (cp * st * cf + sp * sf) * a - kt[0] * v[..., 0]
    out[..., 4] = (sp * st * cf - cp * sf) * a - kt[1] * v[..., 1]
    out[..., 5] = ct * cf * a - kt[2] * v[..., 2] - params.gravity
    p, q, r = omega[..., 0], omega[..., 1], omega[..., 2]
    qs_rc = q * sf + r * cf
    out[..., 6] = p + qs_rc * st / ct
    out[..., 7] = q * cf - r * sf
    out[..., 8] = qs_rc / ct
    out[..., 9:12] = body_angular_accel(params, omega, U[..., 1:], omega_r)
    out[..., 12:16] = (speed_cmd - speeds) / params.motor_time_constant
    return out


def rk4_step(params: QuadrotorParams, state: np.ndarray, speed_cmd: np.ndarray, h: float) -> np.ndarray:
    """One classical Runge–Kutta step of length ``h`` with the command held constant."""
    k1 = truth_derivative(params, state, speed_cmd)
    k2 = truth_derivative(params, state + 0.5 * h * k1, speed_cmd)
    k3 = truth_derivative(params, state + 0.5 * h * k2, speed_cmd)
    k4 = truth_derivative(params, state + h * k3, speed_cmd)
    return state + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
