"""Unit quaternions and rotation vectors, batched over leading axes (numpy only).

Conventions (Solà 2017, "Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508,
whose equation numbers are cited below):

- **Hamilton** quaternions, **scalar first**: ``q = [w, x, y, z]`` (Solà §1.2, eq. 3, 12);
  ``p ⊗ q`` is the Hamilton product (eq. 12).
- A quaternion maps **body → earth**: ``v_earth = q ⊗ [0, v_body] ⊗ q*`` (eq. 115), i.e.
  ``v_earth = R(q) v_body`` with ``R(q)`` of eq. 115. With the ZYX Euler angles (roll φ, pitch θ,
  yaw ψ) ``R = Rz(ψ) Ry(θ) Rx(φ)``, the matrix of :func:`quadest.quadrotor.kinematics.rotation`.
- ``exp`` maps a **rotation vector** ``θ u`` to the unit quaternion ``[cos(θ/2), u sin(θ/2)]``
  (Solà's capital ``Exp``, eq. 101) and ``log`` is its inverse onto angles in [0, π] (eq. 105):
  ``q`` and ``−q`` are the same rotation, and ``log`` picks the representative with ``w ≥ 0``.
- **Right (local, body-frame) perturbation**: ``q ⊞ δθ = q ⊗ exp(δθ)`` and
  ``q ⊟ p = log(p* ⊗ q)`` (Solà §4.1.1, eqs. 160–161, and §7 for the error state), so that
  ``p ⊞ (q ⊟ p) = q`` and the error ``δθ`` is expressed in the body frame of ``p``.

Scipy (``scipy.spatial.transform.Rotation``) is scalar **last**; the tests use it as an independent
reference after reordering.
"""

from __future__ import annotations

import numpy as np

_SMALL_ANGLE = 1e-8


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p ⊗ q`` of quaternions (..., 4) (Solà eq. 12)."""
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def conjugate(q: np.ndarray) -> np.ndarray:
    """``q* = [w, −x, −y, −z]`` (Solà eq. 21); the inverse of a unit quaternion."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def normalize(q: np.ndarray) -> np.ndarray:
    """``q / |q|`` over the last axis."""
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def exp(rotvec: np.ndarray) -> np.ndarray:
    """Unit quaternion (..., 4) of rotation vectors (..., 3): ``[cos(θ/2), v sin(θ/2)/θ]`` with
    ``θ = |v|`` (Solà eq. 101). ``sin(θ/2)/θ = sinc(θ/2π)/2`` is evaluated by ``np.sinc``, exact
    at and near ``θ = 0``."""
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    return np.concatenate([np.cos(0.5 * angle), 0.5 * np.sinc(angle / (2.0 * np.pi)) * rotvec], axis=-1)


def log(q: np.ndarray) -> np.ndarray:
    """Rotation vector (..., 3) of unit quaternions (..., 4), angle in [0, π] (Solà eq. 105).

    ``q`` and ``−q`` give the same vector (the one with ``w ≥ 0`` is used). For ``|v| < 1e-8`` the
    factor ``2 atan2(|v|, w)/|v|`` is replaced by its series ``(2/w)(1 − |v|²/(3w²))``, exact
    to round-off there.
    """
    q = np.where(q[..., :1] < 0.0, -q, q)
    w, v = q[..., :1], q[..., 1:]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    small = n < _SMALL_ANGLE
    safe_n = np.where(small, 1.0, n)
    factor = np.where(small, (2.0 / w) * (1.0 - n**2 / (3.0 * w**2)), 2.0 * np.arctan2(n, w) / safe_n)
    return factor * v


def slerp(p: np.ndarray, q: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation from ``p`` (``fraction`` 0) to ``q`` (``fraction`` 1) along
    the shorter arc: ``p ⊗ exp(τ log(p* ⊗ q))`` (Shoemake 1985, "Animating rotation with quaternion
    curves", SIGGRAPH; Solà 2017 §2.7), for quaternions (..., 4) and fractions (...,).
    ``log`` takes the ``w ≥ 0`` representative, so the arc is at most π."""
    return multiply(p, exp(np.asarray(fraction)[..., None] * log(multiply(conjugate(p), q))))


def rotation_matrix(q: np.ndarray) -> np.ndarray:
    """Body-to-earth rotation matrix (..., 3, 3) of unit quaternions (..., 4) (Solà eq. 115)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    R = np.empty((*q.shape[:-1], 3, 3), dtype=q.dtype)
    R[..., 0, 0] = w * w + x * x - y * y - z * z
    R[..., 0, 1] = 2.0 * (x * y - w * z)
    R[..., 0, 2] = 2.0 * (x * z + w * y)
    R[..., 1, 0] = 2.0 * (x * y + w * z)
    R[..., 1, 1] = w * w - x * x + y * y - z * z
    R[..., 1, 2] = 2.0 * (y * z - w * x)
    R[..., 2, 0] = 2.0 * (x * z - w * y)
    R[..., 2, 1] = 2.0 * (y * z + w * x)
    R[..., 2, 2] = w * w - x * x - y * y + z * z
    return R


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R(q) v`` for vectors (..., 3): body → earth (Solà eq. 115). ``rotate(conjugate(q), v)``
    maps earth → body."""
    return np.einsum("...ij,...j->...i", rotation_matrix(q), v)


def from_euler(angles: np.ndarray) -> np.ndarray:
    """Quaternion (..., 4) of ZYX Euler angles (..., 3) = (roll φ, pitch θ, yaw ψ):
    ``q = q_z(ψ) ⊗ q_y(θ) ⊗ q_x(φ)``, the rotation ``Rz(ψ) Ry(θ) Rx(φ)`` (Solà §3.4 / eq. 115
    applied to the elementary rotations)."""
    half = 0.5 * np.moveaxis(angles, -1, 0)
    cr, cp, cy = np.cos(half)
    sr, sp, sy = np.sin(half)
    return np.stack(
        [
            cy * cp * cr + sy * sp * sr,
            cy * cp * sr - sy * sp * cr,
            cy * sp * cr + sy * cp * sr,
            sy * cp * cr - cy * sp * sr,
        ],
        axis=-1,
    )


def to_euler(q: np.ndarray) -> np.ndarray:
    """ZYX Euler angles (..., 3) = (roll, pitch, yaw) of unit quaternions, inverse of
    :func:`from_euler`; pitch in [−π/2, π/2] (its sine is clipped to [−1, 1] against round-off)."""
    w, x, y, z = np.moveaxis(q, -1, 0)
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def to_mrp(q: np.ndarray) -> np.ndarray:
    """Modified Rodrigues parameters ``p = v/(1 + w)`` (|p| = tan(θ/4); Crassidis & Markley 2003,
    JGCD 26(4), eq. 5), taken from the ``w ≥ 0`` representative so that |p| ≤ 1."""
    q = np.where(q[..., :1] < 0.0, -q, q)
    return q[..., 1:] / (1.0 + q[..., :1])


def from_mrp(p: np.ndarray) -> np.ndarray:
    """Unit quaternion of modified Rodrigues parameters: ``w = (1 − |p|²)/(1 + |p|²)``,
    ``v = 2p/(1 + |p|²)`` (Crassidis & Markley 2003, eq. 6)."""
    s = np.sum(p * p, axis=-1, keepdims=True)
    return np.concatenate([(1.0 - s) / (1.0 + s), 2.0 * p / (1.0 + s)], axis=-1)


def boxplus(q: np.ndarray, dtheta: np.ndarray) -> np.ndarray:
    """``q ⊞ δθ = q ⊗ exp(δθ)``: right (local, body-frame) perturbation (Solà eq. 160)."""
    return multiply(q, exp(dtheta))


def boxminus(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``q ⊟ p = log(p* ⊗ q)``, the body-frame rotation vector from ``p`` to ``q`` (Solà eq. 161);
    ``p ⊞ (q ⊟ p) = q`` up to the sign of ``q``."""
    return log(multiply(conjugate(p), q))


def skew(v: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix ``[v]×`` (..., 3, 3) with ``[v]× a = v × a`` (Solà eq. 9)."""
    out = np.zeros((*v.shape[:-1], 3, 3), dtype=v.dtype)
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def right_jacobian(rotvec: np.ndarray) -> np.ndarray:
    """Right Jacobian of SO(3) (..., 3, 3): ``exp(θ + δ) ≈ exp(θ) ⊗ exp(J_r(θ) δ)`` (Solà eq. 143):
    ``J_r = I − (1 − cos θ)/θ² [θ]× + (θ − sin θ)/θ³ [θ]×²``, with the series
    ``1/2 − θ²/24`` and ``1/6 − θ²/120`` for the coefficients below θ = 1e-4 (cancellation)."""
    angle = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    small = angle < 1e-4
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    b = np.where(small, 1.0 / 6.0 - angle**2 / 120.0, (safe - np.sin(safe)) / safe**3)
    K = skew(rotvec)
    return np.eye(3) - a * K + b * (K @ K)
