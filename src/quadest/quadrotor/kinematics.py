"""ZYX Euler-angle kinematics, vectorised over leading axes.

Earth frame z up; ``R(Θ) = Rz(ψ) Ry(θ) Rx(φ)`` maps body to earth; body rates ``ω = W(Θ) Θ̇``
(thesis eq. 2.64 in inverse form). Every function accepts complex input so that derivatives can
be checked by the complex step.
"""

from __future__ import annotations

import numpy as np


def _stack3x3(rows: list[list[np.ndarray]]) -> np.ndarray:
    """A (..., 3, 3) array from nine broadcastable entries (filled in place: cheaper than
    stacking for the small arrays of a single-run filter)."""
    entries = [e for row in rows for e in row]
    out = np.empty((*np.broadcast_shapes(*(np.shape(e) for e in entries)), 3, 3), dtype=np.result_type(*entries))
    for i, row in enumerate(rows):
        for j, e in enumerate(row):
            out[..., i, j] = e
    return out


def rotation(angles: np.ndarray) -> np.ndarray:
    """Body-to-earth rotation ``R(Θ)`` (..., 3, 3) for angles (..., 3) = (φ, θ, ψ)."""
    sf, cf = np.sin(angles[..., 0]), np.cos(angles[..., 0])
    st, ct = np.sin(angles[..., 1]), np.cos(angles[..., 1])
    sp, cp = np.sin(angles[..., 2]), np.cos(angles[..., 2])
    return _stack3x3(
        [
            [cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf],
            [sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf],
            [-st, ct * sf, ct * cf],
        ]
    )


def rate_matrix(angles: np.ndarray) -> np.ndarray:
    """``W(Θ)`` (..., 3, 3) with ``ω = W Θ̇``."""
    sf, cf = np.sin(angles[..., 0]), np.cos(angles[..., 0])
    st, ct = np.sin(angles[..., 1]), np.cos(angles[..., 1])
    one, zero = np.ones_like(sf), np.zeros_like(sf)
    return _stack3x3([[one, zero, -st], [zero, cf, sf * ct], [zero, -sf, cf * ct]])


def rate_matrix_inv(angles: np.ndarray) -> np.ndarray:
    """``W(Θ)⁻¹`` (..., 3, 3) with ``Θ̇ = W⁻¹ ω`` (thesis eq. 2.64)."""
    sf, cf = np.sin(angles[..., 0]), np.cos(angles[..., 0])
    tt, sec = np.tan(angles[..., 1]), 1.0 / np.cos(angles[..., 1])
    one, zero = np.ones_like(sf), np.zeros_like(sf)
    return _stack3x3([[one, sf * tt, cf * tt], [zero, cf, -sf], [zero, sf * sec, cf * sec]])


def rate_matrix_inv_partials(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``∂W⁻¹/∂φ`` and ``∂W⁻¹/∂θ`` (each ..., 3, 3).

    ``d/dt W⁻¹ = ∂W⁻¹/∂φ · φ̇ + ∂W⁻¹/∂θ · θ̇``. The first matrix of thesis eq. 5.31 is this sum
    with the factors φ̇ and θ̇ left out; we use the derivative with them.
    """
    sf, cf = np.sin(angles[..., 0]), np.cos(angles[..., 0])
    tt, sec = np.tan(angles[..., 1]), 1.0 / np.cos(angles[..., 1])
    zero = np.zeros_like(sf)
    d_phi = _stack3x3([[zero, cf * tt, -sf * tt], [zero, -sf, -cf], [zero, cf * sec, -sf * sec]])
    d_theta = _stack3x3(
        [
            [zero, sf * sec**2, cf * sec**2],
            [zero, zero, zero],
            [zero, sf * tt * sec, cf * tt * sec],
        ]
    )
    return d_phi, d_theta


def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x`` over leading axes: A (..., i, j), x (..., j) → (..., i)."""
    return np.einsum("...ij,...j->...i", A, x)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap angles to (−π, π]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)
