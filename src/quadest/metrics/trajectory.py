"""Trajectory errors against a reference (docs/metrics.md, "Trajectory errors: ATE and RPE"):
the absolute trajectory error after alignment and the relative pose error over sub-trajectory
lengths, as Zhang & Scaramuzza (2018, "A tutorial on quantitative trajectory evaluation for
visual(-inertial) odometry", IROS) define them.

A trajectory is its positions ``p`` (N, 3) and attitudes ``q`` (N, 4), Hamilton quaternions scalar
first, body → world (:mod:`quadest.numerics.quaternion`), the estimate and the reference sampled
at the same N times.

- **Alignment** (Zhang & Scaramuzza, "trajectory alignment"): the transform ``(R, t)`` that minimises
  ``Σ_i |p_ref,i − (R p_est,i + t)|²``. SE(3), rotation and translation without scale (their
  choice for stereo visual odometry): Umeyama (1991, "Least-squares estimation of
  transformation parameters between two point patterns", IEEE PAMI 13(4)) with the scale fixed to
  1, ``R = U S Vᵀ`` from the SVD ``U D Vᵀ`` of the cross-covariance ``Σ_xy = (1/N) Σ (y − μ_y)(x − μ_x)ᵀ``
  (x the estimate, y the reference; eq. 38), ``S = diag(1, 1, det U det V)`` (eq. 43), and
  ``t = μ_y − R μ_x`` (eq. 41 with c = 1). 4-DoF, translation and yaw (their choice for
  visual-inertial systems, whose roll and pitch are observable from gravity): ``R = Rz(ψ)`` with the ψ that maximises
  ``Σ (y − μ_y)ᵀ Rz(ψ) (x − μ_x)``, ``ψ = atan2(Σ (x_x y_y − x_y y_x), Σ (x_x y_x + x_y y_y))`` on the
  centred coordinates, and the same ``t``.
- **ATE** (their "absolute trajectory error"): with ``p̂_i = R p_est,i + t`` and
  ``R̂_i = R R_est,i``, the position error ``|p_ref,i − p̂_i|`` (as their toolbox,
  rpg_trajectory_evaluation, and evo compute it) and the rotation error, the angle of
  ``R_ref,i R̂_iᵀ``; the ATE is the RMS of each over the trajectory.
- **RPE** (their "relative error"): for a sub-trajectory length ``d``, the pairs ``(i, j)`` whose distance
  travelled along the reference from ``i`` to ``j`` is closest to ``d`` (j > i, within
  ``rel_tol · d``, one pair per start i); for each, the relative motions ``δ_ref = T_ref,i⁻¹ T_ref,j``
  and ``δ_est = T_est,i⁻¹ T_est,j`` and their difference ``E = δ_ref⁻¹ δ_est`` (Sturm et al. 2012,
  "A benchmark for the evaluation of RGB-D SLAM systems", IROS, eq. 1): the translation error
  ``|t(E)|`` and the rotation error, the angle of ``R(E)``. It needs no alignment: relative motions
  do not see a global transform.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from quadest.numerics import quaternion as quat

ALIGNMENTS = ("se3", "4dof")


@dataclass(frozen=True)
class Alignment:
    """``p_ref ≈ rotation @ p_est + translation``: ``rotation`` (3, 3), ``translation`` (3,)."""

    rotation: np.ndarray
    translation: np.ndarray


@dataclass(frozen=True)
class AbsoluteError:
    """The ATE of one trajectory: the alignment used, the position errors (N,) in metres and the
    rotation errors (N,) in radians after it, and their RMS (``position_rmse``, ``rotation_rmse``)."""

    alignment: Alignment
    position: np.ndarray
    rotation: np.ndarray

    @property
    def position_rmse(self) -> float:
        return float(np.sqrt(np.mean(self.position**2)))

    @property
    def rotation_rmse(self) -> float:
        return float(np.sqrt(np.mean(self.rotation**2)))


@dataclass(frozen=True)
class RelativeError:
    """The RPE of one trajectory at one sub-trajectory length ``distance`` (m): the index pairs
    (P, 2), the translation errors (P,) in metres and the rotation errors (P,) in radians."""

    distance: float
    pairs: np.ndarray
    translation: np.ndarray
    rotation: np.ndarray


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """The angle (rad, in [0, π]) of rotation matrices (..., 3, 3): ``atan2(sin θ, cos θ)`` with
    ``cos θ = (tr R − 1)/2`` and ``sin θ`` the norm of the axial vector of ``(R − Rᵀ)/2``, accurate
    near 0 and π where ``arccos`` alone loses half the digits."""
    axial = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    return np.arctan2(0.5 * np.linalg.norm(axial, axis=-1), 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0))


def align(estimate: np.ndarray, reference: np.ndarray, kind: str = "se3") -> Alignment:
    """The least-squares alignment of positions ``estimate`` onto ``reference`` (N, 3) (module
    docstring): ``kind`` ``"se3"`` (Umeyama 1991 without scale) or ``"4dof"`` (translation and yaw).

    Raises:
        ValueError: an unknown ``kind``, shapes that differ, or points too few or collinear to fix
            the rotation.
    """
    if kind not in ALIGNMENTS:
        raise ValueError(f"alignment must be one of {ALIGNMENTS}, got {kind!r}")
    x, y = np.asarray(estimate, dtype=float), np.asarray(reference, dtype=float)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"positions must both be (N, 3), got {x.shape} and {y.shape}")
    mu_x, mu_y = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mu_x, y - mu_y
    if kind == "se3":
        cov = yc.T @ xc / x.shape[0]
        U, D, Vt = np.linalg.svd(cov)
        if np.count_nonzero(D > 1e-12 * max(D[0], np.finfo(float).tiny)) < 2:
            raise ValueError("the positions are too few or collinear to fix a rotation")
        S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt))])
        R = U @ S @ Vt
    else:
        yaw = np.arctan2(
            np.sum(xc[:, 0] * yc[:, 1] - xc[:, 1] * yc[:, 0]), np.sum(xc[:, 0] * yc[:, 0] + xc[:, 1] * yc[:, 1])
        )
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Alignment(R, mu_y - R @ mu_x)


def absolute_error(
    p_est: np.ndarray, q_est: np.ndarray, p_ref: np.ndarray, q_ref: np.ndarray, kind: str = "se3"
) -> AbsoluteError:
    """The ATE of the estimate against the reference after alignment ``kind`` (module docstring)."""
    a = align(p_est, p_ref, kind)
    aligned = p_est @ a.rotation.T + a.translation
    R_hat = a.rotation @ quat.rotation_matrix(q_est)
    R_err = quat.rotation_matrix(q_ref) @ np.swapaxes(R_hat, -1, -2)
    return AbsoluteError(a, np.linalg.norm(p_ref - aligned, axis=-1), rotation_angle(R_err))


def travelled(positions: np.ndarray) -> np.ndarray:
    """The distance (N,) travelled from the first position, along the polyline of ``positions``."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=-1))])


def distance_pairs(positions: np.ndarray, distance: float, rel_tol: float = 0.1) -> np.ndarray:
    """The pairs (P, 2) ``(i, j)``, j > i, whose distance travelled along ``positions`` from i to j
    is the closest to ``distance``, kept when within ``rel_tol · distance`` (module docstring)."""
    s = travelled(positions)
    pairs = []
    for i in range(s.size - 1):
        j = i + 1 + int(np.argmin(np.abs(s[i + 1 :] - s[i] - distance)))
        if abs(s[j] - s[i] - distance) <= rel_tol * distance:
            pairs.append((i, j))
    return np.array(pairs, dtype=int).reshape(-1, 2)


def _poses(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return quat.rotation_matrix(q), np.asarray(p, dtype=float)


def relative_errors(
    p_est: np.ndarray,
    q_est: np.ndarray,
    p_ref: np.ndarray,
    q_ref: np.ndarray,
    distances: Sequence[float],
    rel_tol: float = 0.1,
) -> list[RelativeError]:
    """The RPE of the estimate against the reference at each sub-trajectory length of
    ``distances`` (m), pairs chosen along the reference (module docstring). A length the
    reference never travels gives no pairs (empty arrays)."""
    R_est, t_est = _poses(p_est, q_est)
    R_ref, t_ref = _poses(p_ref, q_ref)
    out = []
    for d in distances:
        pairs = distance_pairs(p_ref, float(d), rel_tol)
        i, j = pairs[:, 0], pairs[:, 1]

        def relative(R, t, i=i, j=j):
            Ri_T = np.swapaxes(R[i], -1, -2)
            return Ri_T @ R[j], np.einsum("pab,pb->pa", Ri_T, t[j] - t[i])

        dR_ref, dt_ref = relative(R_ref, t_ref)
        dR_est, dt_est = relative(R_est, t_est)
        dR_ref_T = np.swapaxes(dR_ref, -1, -2)
        E_R = dR_ref_T @ dR_est
        E_t = np.einsum("pab,pb->pa", dR_ref_T, dt_est - dt_ref)
        out.append(RelativeError(float(d), pairs, np.linalg.norm(E_t, axis=-1), rotation_angle(E_R)))
    return out
