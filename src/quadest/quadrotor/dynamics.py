"""Rigid-body and rotor dynamics of the quadrotor (OS4: Bouabdallah & Siegwart 2005; docs/sources.md).

Truth state (16): ``[p (3), v (3), Θ (3), ω (3), Ω (4)]`` — earth-frame position and velocity,
ZYX Euler angles, body rates and the four actual rotor speeds. All functions work over leading
axes and accept complex input (for complex-step derivative checks).

- ``m v̇ = R(Θ) [0, 0, U1]ᵀ − m g e_z − Kt v``
- ``I ω̇ = −ω × Iω − Jr (ω × e_z) Ωr + [U2, U3, U4]ᵀ − Kr ω``
- ``Θ̇ = W(Θ)⁻¹ ω``,  ``ṗ = v``,  ``τm Ω̇ = Ω_cmd − Ω`` (first-order motor lag)
"""

from __future__ import annotations

import numpy as np

from quadest.quadrotor.params import QuadrotorParams

TRUTH_STATE_NAMES = (
    "x", "y", "z", "vx", "vy", "vz", "phi", "theta", "psi", "p", "q", "r",
    "rotor1", "rotor2", "rotor3", "rotor4",
)  # fmt: skip


def rotor_inputs(params: QuadrotorParams, speeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Thrust and torques ``U = [U1, U2, U3, U4]`` (..., 4) and the rotor gyroscopic speed
    ``Ωr = Ω1 − Ω2 + Ω3 − Ω4`` (...) from rotor speeds (..., 4), OS4 convention:
    ``U1 = b ΣΩi²``, ``U2 = l b (Ω4² − Ω2²)``, ``U3 = l b (Ω3² − Ω1²)``,
    ``U4 = d (Ω1² − Ω2² + Ω3² − Ω4²)`` (the rows of ``params.mixer``)."""
    sq = speeds * speeds
    b, d, lb = params.thrust_factor, params.drag_factor, params.arm * params.thrust_factor
    U = np.empty(sq.shape, dtype=sq.dtype)
    U[..., 0] = b * (sq[..., 0] + sq[..., 1] + sq[..., 2] + sq[..., 3])
    U[..., 1] = lb * (sq[..., 3] - sq[..., 1])
    U[..., 2] = lb * (sq[..., 2] - sq[..., 0])
    U[..., 3] = d * (sq[..., 0] - sq[..., 1] + sq[..., 2] - sq[..., 3])
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


def body_rate_jacobian(params: QuadrotorParams, omega: np.ndarray, omega_r: np.ndarray) -> np.ndarray:
    """``∂ω̇/∂ω`` (..., 3, 3) of :func:`body_angular_accel` at the body rates ``omega`` (..., 3),
    with the rotor speed sum ``omega_r`` broadcastable to ``omega[..., 0]`` (the torques do not
    depend on ω)."""
    ix, iy, iz = params.inertia
    kr = params.kr
    jw = params.rotor_inertia * omega_r
    p, q, r = omega[..., 0], omega[..., 1], omega[..., 2]
    zero = np.zeros_like(p)
    rows = [
        [zero - kr[0] / ix, ((iy - iz) * r - jw) / ix, (iy - iz) * q / ix],
        [((iz - ix) * r + jw) / iy, zero - kr[1] / iy, (iz - ix) * p / iy],
        [(ix - iy) * q / iz, (ix - iy) * p / iz, zero - kr[2] / iz],
    ]
    return np.stack([np.stack(np.broadcast_arrays(*row), axis=-1) for row in rows], axis=-2)


def _trig(angles: np.ndarray) -> tuple[np.ndarray, ...]:
    return (
        np.sin(angles[..., 0]),
        np.cos(angles[..., 0]),
        np.sin(angles[..., 1]),
        np.cos(angles[..., 1]),
        np.sin(angles[..., 2]),
        np.cos(angles[..., 2]),
    )


def translational_accel(params: QuadrotorParams, angles: np.ndarray, v: np.ndarray, thrust: np.ndarray) -> np.ndarray:
    """``v̇`` (..., 3) in the earth frame: ``R(Θ) e_z U1/m − g e_z − Kt v/m``, element by element
    (the third column of ``R(Θ)`` is the body z axis)."""
    sf, cf, st, ct, sp, cp = _trig(angles)
    a = thrust / params.mass
    kt = params.kt / params.mass
    shape = np.broadcast_shapes(angles.shape, v.shape, (*thrust.shape, 3))
    out = np.empty(shape, dtype=np.result_type(angles, v, thrust))
    out[..., 0] = (cp * st * cf + sp * sf) * a - kt[0] * v[..., 0]
    out[..., 1] = (sp * st * cf - cp * sf) * a - kt[1] * v[..., 1]
    out[..., 2] = ct * cf * a - kt[2] * v[..., 2] - params.gravity
    return out


def specific_force(params: QuadrotorParams, angles: np.ndarray, v: np.ndarray, thrust: np.ndarray) -> np.ndarray:
    """What an ideal accelerometer measures: ``f_b = Rᵀ (v̇ + g e_z) = e_z U1/m − Rᵀ Kt v / m``.

    Component i of ``Rᵀ d`` is column i of ``R(Θ)`` dotted with ``d``."""
    sf, cf, st, ct, sp, cp = _trig(angles)
    kt = params.kt / params.mass
    d0, d1, d2 = kt[0] * v[..., 0], kt[1] * v[..., 1], kt[2] * v[..., 2]
    shape = np.broadcast_shapes(angles.shape, v.shape, (*thrust.shape, 3))
    out = np.empty(shape, dtype=np.result_type(angles, v, thrust))
    out[..., 0] = -(cp * ct * d0 + sp * ct * d1 - st * d2)
    out[..., 1] = -((cp * st * sf - sp * cf) * d0 + (sp * st * sf + cp * cf) * d1 + ct * sf * d2)
    out[..., 2] = thrust / params.mass - ((cp * st * cf + sp * sf) * d0 + (sp * st * cf - cp * sf) * d1 + ct * cf * d2)
    return out


def euler_rates(angles: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """``Θ̇ = W(Θ)⁻¹ ω`` (thesis eq. 2.64): ``φ̇ = p + (q sφ + r cφ) tθ``, ``θ̇ = q cφ − r sφ``,
    ``ψ̇ = (q sφ + r cφ)/cθ``."""
    sf, cf = np.sin(angles[..., 0]), np.cos(angles[..., 0])
    tt, ct = np.tan(angles[..., 1]), np.cos(angles[..., 1])
    p, q, r = omega[..., 0], omega[..., 1], omega[..., 2]
    a = q * sf + r * cf
    out = np.empty(np.broadcast_shapes(angles.shape, omega.shape), dtype=np.result_type(angles, omega))
    out[..., 0] = p + a * tt
    out[..., 1] = q * cf - r * sf
    out[..., 2] = a / ct
    return out


def body_rates(angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """``ω = W(Θ) Θ̇``: ``p = φ̇ − sθ ψ̇``, ``q = cφ θ̇ + sφ cθ ψ̇``, ``r = −sφ θ̇ + cφ cθ ψ̇``."""
    sf, cf = np.sin(angles[..., 0]), np.cos(angles[..., 0])
    st, ct = np.sin(angles[..., 1]), np.cos(angles[..., 1])
    out = np.empty(np.broadcast_shapes(angles.shape, rates.shape), dtype=np.result_type(angles, rates))
    out[..., 0] = rates[..., 0] - st * rates[..., 2]
    out[..., 1] = cf * rates[..., 1] + sf * ct * rates[..., 2]
    out[..., 2] = -sf * rates[..., 1] + cf * ct * rates[..., 2]
    return out


def euler_angle_accel(params: QuadrotorParams, angles: np.ndarray, rates: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """Euler-angle accelerations ``Θ̈ = (d/dt W⁻¹) ω + W⁻¹ ω̇`` (thesis eq. 5.31).

    ``angles`` and ``rates`` are Θ and Θ̇ (..., 3); ``speeds`` the rotor speeds (..., 4). With
    ``a = q sφ + r cφ`` and ``c = q cφ − r sφ``: ``∂W⁻¹/∂φ ω = (tθ c, −a, c/cθ)`` and
    ``∂W⁻¹/∂θ ω = (a/cθ², 0, a tθ/cθ)``. (The first matrix printed in eq. 5.31 is the sum of
    the two partials without the factors φ̇ and θ̇; we use the time derivative.)
    """
    U, omega_r = rotor_inputs(params, speeds)
    return euler_angle_accel_from_inputs(params, angles, rates, U[..., 1:], omega_r)


def euler_angle_accel_from_inputs(
    params: QuadrotorParams, angles: np.ndarray, rates: np.ndarray, torques: np.ndarray, omega_r: np.ndarray
) -> np.ndarray:
    """:func:`euler_angle_accel` from the torques and ``Ωr`` (when the caller has them already)."""
    omega = body_rates(angles, rates)
    wd = body_angular_accel(params, omega, torques, omega_r)
    sf, cf = np.sin(angles[..., 0]), np.cos(angles[..., 0])
    tt, sec = np.tan(angles[..., 1]), 1.0 / np.cos(angles[..., 1])
    q, r = omega[..., 1], omega[..., 2]
    a, c = q * sf + r * cf, q * cf - r * sf
    ad = wd[..., 1] * sf + wd[..., 2] * cf
    phi_dot, theta_dot = rates[..., 0], rates[..., 1]
    out = np.empty(omega.shape, dtype=omega.dtype)
    out[..., 0] = phi_dot * tt * c + theta_dot * sec * sec * a + wd[..., 0] + tt * ad
    out[..., 1] = -phi_dot * a + wd[..., 1] * cf - wd[..., 2] * sf
    out[..., 2] = phi_dot * sec * c + theta_dot * tt * sec * a + sec * ad
    return out


def truth_derivative(params: QuadrotorParams, state: np.ndarray, speed_cmd: np.ndarray) -> np.ndarray:
    """Time derivative of the 16-state truth (..., 16) under commanded rotor speeds (..., 4)."""
    v, angles, omega, speeds = state[..., 3:6], state[..., 6:9], state[..., 9:12], state[..., 12:16]
    U, omega_r = rotor_inputs(params, speeds)
    out = np.empty(np.broadcast_shapes(state.shape, (*speed_cmd.shape[:-1], 16)), dtype=state.dtype)
    out[..., 0:3] = v
    out[..., 3:6] = translational_accel(params, angles, v, U[..., 0])
    out[..., 6:9] = euler_rates(angles, omega)
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
