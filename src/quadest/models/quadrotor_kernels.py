"""Compiled (numba) ``f`` and ``h`` of the quadrotor filter models (:mod:`quadest.models.quadrotor`).

The same expressions as the numpy reference (``QuadrotorFilterModel.f_numpy``/``h_numpy`` and
:mod:`quadest.quadrotor.dynamics`), evaluated point by point in one loop instead of some 60 numpy
passes over all sigma points, for a batch of sigma points ``x`` (B, K, n) of runs with inputs
``u`` (B, nu):

- ``f`` (seed 000, eqs 5.30–5.32, forward Euler with period T): ``v⁺ = v + T (R(Θ) e_z U1/m − g e_z
  − Kt v/m)``, ``Θ̇⁺ = Θ̇ + T Θ̈`` with ``Θ̈ = (d/dt W⁻¹) ω + W⁻¹ ω̇`` (eq. 5.31), and for the augmented
  formulation ``Θ⁺ = Θ + T Θ̇``;
- ``h``: the specific force ``e_z U1/m − Rᵀ Kt v/m`` and the body rates ``W(Θ) Θ̇`` through each
  triad's deterministic errors ``(I + S + M) y + S± ⊙ sgn(y) y + b0`` (thesis §5.3.1).

``p`` is ``quadest.models.quadrotor.packed_params``. The thesis formulation takes the angles from ``u[:, 4:7]`` (one
set per run, so their sines and cosines are computed once per run, before the loop over the points),
the augmented one from the state.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_JIT = {"cache": True, "error_model": "numpy", "nogil": True}

# Positions in the packed parameter vector (quadest.models.quadrotor.packed_params).
_B, _D, _LB, _MASS, _G, _JR = 0, 1, 2, 3, 4, 5
_KT, _IN, _KR = 6, 9, 12


@njit(**_JIT)
def _inputs(p: np.ndarray, s: np.ndarray) -> tuple[float, float, float, float, float]:
    """``U1..U4`` and ``Ωr`` from the rotor speeds ``s`` (4,) (OS4 mixer, eq. 5.31's inputs)."""
    s0, s1, s2, s3 = s[0] * s[0], s[1] * s[1], s[2] * s[2], s[3] * s[3]
    U1 = p[_B] * (s0 + s1 + s2 + s3)
    U2 = p[_LB] * (s3 - s1)
    U3 = p[_LB] * (s2 - s0)
    U4 = p[_D] * (s0 - s1 + s2 - s3)
    return U1, U2, U3, U4, s[0] - s[1] + s[2] - s[3]


@njit(**_JIT)
def _trig(phi: float, theta: float, psi: float) -> tuple[float, float, float, float, float, float, float, float]:
    """``sin φ, cos φ, sin θ, cos θ, sin ψ, cos ψ, tan θ, sec θ``: once per run for the thesis
    formulation (angles from the input), once per point for the augmented one."""
    ct = math.cos(theta)
    return math.sin(phi), math.cos(phi), math.sin(theta), ct, math.sin(psi), math.cos(psi), math.tan(theta), 1.0 / ct


@njit(**_JIT)
def quadrotor_f(x: np.ndarray, u: np.ndarray, p: np.ndarray, thesis: bool, T: float, out: np.ndarray) -> None:
    """``out = f(x, u)`` for sigma points ``x`` (B, K, n); the rates sit at 3:6 (thesis) or 6:9."""
    B, K, _ = x.shape
    rs = 3 if thesis else 6
    ix, iy, iz = p[_IN], p[_IN + 1], p[_IN + 2]
    kt0, kt1, kt2 = p[_KT] / p[_MASS], p[_KT + 1] / p[_MASS], p[_KT + 2] / p[_MASS]
    for b in range(B):
        U1, U2, U3, U4, omega_r = _inputs(p, u[b])
        a = U1 / p[_MASS]
        jw = p[_JR] * omega_r
        phi, theta, psi = (u[b, 4], u[b, 5], u[b, 6]) if thesis else (0.0, 0.0, 0.0)
        sf, cf, st, ct, sp, cp, tt, sec = _trig(phi, theta, psi)
        for k in range(K):
            if not thesis:
                phi, theta, psi = x[b, k, 3], x[b, k, 4], x[b, k, 5]
                sf, cf, st, ct, sp, cp, tt, sec = _trig(phi, theta, psi)
            v0, v1, v2 = x[b, k, 0], x[b, k, 1], x[b, k, 2]
            out[b, k, 0] = v0 + T * ((cp * st * cf + sp * sf) * a - kt0 * v0)
            out[b, k, 1] = v1 + T * ((sp * st * cf - cp * sf) * a - kt1 * v1)
            out[b, k, 2] = v2 + T * (ct * cf * a - kt2 * v2 - p[_G])
            phi_dot, theta_dot, psi_dot = x[b, k, rs], x[b, k, rs + 1], x[b, k, rs + 2]
            wp = phi_dot - st * psi_dot
            wq = cf * theta_dot + sf * ct * psi_dot
            wr = -sf * theta_dot + cf * ct * psi_dot
            wd0 = ((iy - iz) * wq * wr - jw * wq + U2 - p[_KR] * wp) / ix
            wd1 = ((iz - ix) * wp * wr + jw * wp + U3 - p[_KR + 1] * wq) / iy
            wd2 = ((ix - iy) * wp * wq + U4 - p[_KR + 2] * wr) / iz
            ac, cc = wq * sf + wr * cf, wq * cf - wr * sf
            ad = wd1 * sf + wd2 * cf
            out[b, k, rs] = phi_dot + T * (phi_dot * tt * cc + theta_dot * sec * sec * ac + wd0 + tt * ad)
            out[b, k, rs + 1] = theta_dot + T * (-phi_dot * ac + wd1 * cf - wd2 * sf)
            out[b, k, rs + 2] = psi_dot + T * (phi_dot * sec * cc + theta_dot * tt * sec * ac + sec * ad)
            if not thesis:
                out[b, k, 3] = phi + T * phi_dot
                out[b, k, 4] = theta + T * theta_dot
                out[b, k, 5] = psi + T * psi_dot


@njit(**_JIT)
def _triad(M: np.ndarray, asym: np.ndarray, bias: np.ndarray, y0: float, y1: float, y2: float, out: np.ndarray):
    """``out = M y + asym ⊙ sgn(y) y + bias`` for one triad of one run."""
    for i in range(3):
        yi = y0 if i == 0 else y1 if i == 1 else y2
        linear = M[i, 0] * y0 + M[i, 1] * y1 + M[i, 2] * y2
        out[i] = linear + asym[i] * np.sign(yi) * yi + bias[i]


@njit(**_JIT)
def quadrotor_h(
    x: np.ndarray,
    u: np.ndarray,
    p: np.ndarray,
    thesis: bool,
    acc_matrix: np.ndarray,
    acc_asym: np.ndarray,
    acc_bias: np.ndarray,
    gyro_matrix: np.ndarray,
    gyro_asym: np.ndarray,
    gyro_bias: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out = h(x, u)`` (B, K, 6): accelerometer then gyro, each through its triad errors."""
    B, K, _ = x.shape
    rs = 3 if thesis else 6
    kt0, kt1, kt2 = p[_KT] / p[_MASS], p[_KT + 1] / p[_MASS], p[_KT + 2] / p[_MASS]
    for b in range(B):
        U1 = _inputs(p, u[b])[0]
        phi, theta, psi = (u[b, 4], u[b, 5], u[b, 6]) if thesis else (0.0, 0.0, 0.0)
        sf, cf, st, ct, sp, cp, _, _ = _trig(phi, theta, psi)
        for k in range(K):
            if not thesis:
                phi, theta, psi = x[b, k, 3], x[b, k, 4], x[b, k, 5]
                sf, cf, st, ct, sp, cp, _, _ = _trig(phi, theta, psi)
            d0, d1, d2 = kt0 * x[b, k, 0], kt1 * x[b, k, 1], kt2 * x[b, k, 2]
            f0 = -(cp * ct * d0 + sp * ct * d1 - st * d2)
            f1 = -((cp * st * sf - sp * cf) * d0 + (sp * st * sf + cp * cf) * d1 + ct * sf * d2)
            f2 = U1 / p[_MASS] - ((cp * st * cf + sp * sf) * d0 + (sp * st * cf - cp * sf) * d1 + ct * cf * d2)
            _triad(acc_matrix[b], acc_asym[b], acc_bias[b], f0, f1, f2, out[b, k, 0:3])
            phi_dot, theta_dot, psi_dot = x[b, k, rs], x[b, k, rs + 1], x[b, k, rs + 2]
            g0 = phi_dot - st * psi_dot
            g1 = cf * theta_dot + sf * ct * psi_dot
            g2 = -sf * theta_dot + cf * ct * psi_dot
            _triad(gyro_matrix[b], gyro_asym[b], gyro_bias[b], g0, g1, g2, out[b, k, 3:6])
