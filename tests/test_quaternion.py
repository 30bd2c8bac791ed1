"""Quaternion numerics against scipy's Rotation (scalar last) as an independent reference, and
the round trips the error-state filters rely on. Tolerances: every function is a few dozen
floating-point operations on O(1) numbers, so results agree to ~1e-15; 1e-12 leaves room for the
conditioning of arctan/arcsin near their branch points without hiding an error (a wrong sign or
convention gives O(1) differences)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from quadest.numerics import quaternion as quat
from quadest.quadrotor.kinematics import rotation

TOL = 1e-12


def _scipy(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(q[..., [1, 2, 3, 0]])


def _from_scipy(r: Rotation) -> np.ndarray:
    return r.as_quat()[..., [3, 0, 1, 2]]


@pytest.fixture
def quaternions() -> np.ndarray:
    rng = np.random.default_rng(11)
    return quat.normalize(rng.standard_normal((4, 5, 4)))  # batched over two leading axes


@pytest.fixture
def rotvecs() -> np.ndarray:
    rng = np.random.default_rng(12)
    v = rng.standard_normal((20, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True) * rng.uniform(0.0, 3.0, (20, 1))


def _same_rotation(p: np.ndarray, q: np.ndarray) -> float:
    """Distance that ignores the quaternion sign ambiguity."""
    return float(np.minimum(np.abs(p - q).max(-1), np.abs(p + q).max(-1)).max())


def test_product_and_conjugate_match_scipy(quaternions):
    p, q = quaternions, quaternions[::-1]
    ref = _from_scipy(_scipy(p.reshape(-1, 4)) * _scipy(q.reshape(-1, 4))).reshape(p.shape)
    assert _same_rotation(quat.multiply(p, q), ref) < TOL
    assert np.abs(quat.multiply(p, quat.conjugate(p)) - [1, 0, 0, 0]).max() < TOL


def test_rotation_matrix_and_rotate_match_scipy(quaternions):
    q = quaternions.reshape(-1, 4)
    assert np.abs(quat.rotation_matrix(q) - _scipy(q).as_matrix()).max() < TOL
    v = np.random.default_rng(3).standard_normal((q.shape[0], 3))
    assert np.abs(quat.rotate(q, v) - _scipy(q).apply(v)).max() < TOL
    # the sandwich q ⊗ [0, v] ⊗ q* is the same map (Solà eq. 115)
    pure = np.concatenate([np.zeros((q.shape[0], 1)), v], axis=-1)
    sandwich = quat.multiply(quat.multiply(q, pure), quat.conjugate(q))
    assert np.abs(sandwich[:, 1:] - quat.rotate(q, v)).max() < TOL


def test_exp_log_match_scipy_and_round_trip(rotvecs):
    q = quat.exp(rotvecs)
    assert _same_rotation(q, _from_scipy(Rotation.from_rotvec(rotvecs))) < TOL
    assert np.abs(quat.log(q) - rotvecs).max() < TOL
    assert np.abs(quat.log(-q) - rotvecs).max() < TOL  # q and -q are one rotation


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-9, 1e-7, 1e-5])
def test_exp_log_are_accurate_near_zero(angle):
    v = angle * np.array([0.6, -0.8, 0.0])
    q = quat.exp(v)
    assert np.abs(np.linalg.norm(q) - 1.0) < 1e-15
    assert np.abs(q[1:] - 0.5 * v).max() <= 1e-16 + angle**3  # sin(θ/2)/θ = 1/2 − θ²/48
    assert np.abs(quat.log(q) - v).max() <= 1e-15 * max(angle, 1e-300) + 1e-300


def test_euler_round_trip_and_scipy(quaternions):
    rng = np.random.default_rng(5)
    angles = np.stack(
        [rng.uniform(-np.pi, np.pi, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-np.pi, np.pi, 50)], axis=-1
    )
    q = quat.from_euler(angles)
    ref = _from_scipy(Rotation.from_euler("ZYX", angles[:, ::-1]))
    assert _same_rotation(q, ref) < TOL
    assert np.abs(quat.to_euler(q) - angles).max() < TOL
    assert np.abs(quat.rotation_matrix(q) - rotation(angles)).max() < TOL  # the quadrotor's R(Θ)


def test_mrp_round_trip_and_scipy(quaternions):
    q = quaternions.reshape(-1, 4)
    assert np.abs(quat.to_mrp(q) - _scipy(q).as_mrp()).max() < TOL
    assert _same_rotation(quat.from_mrp(quat.to_mrp(q)), q) < TOL


def test_boxplus_boxminus_round_trips(quaternions, rotvecs):
    q = quaternions.reshape(-1, 4)[:20]
    p = quat.normalize(q + 0.3 * np.random.default_rng(9).standard_normal(q.shape))
    assert _same_rotation(quat.boxplus(p, quat.boxminus(q, p)), q) < TOL
    assert np.abs(quat.boxminus(quat.boxplus(q, rotvecs), q) - rotvecs).max() < TOL
    # right perturbation: the error is in p's body frame, q = p ⊗ exp(δ) (not exp(δ) ⊗ p)
    d = quat.boxminus(q, p)
    assert np.abs(_scipy(q).as_rotvec() - (_scipy(p) * Rotation.from_rotvec(d)).as_rotvec()).max() < 1e-10


def test_right_jacobian_against_finite_differences(rotvecs):
    """exp(θ + δ) ≈ exp(θ) ⊗ exp(J_r δ): central differences of log(exp(θ)* ⊗ exp(θ + δ)), with
    error O(h²) ≈ 1e-12 at h = 1e-6 plus round-off 1e-16/h = 1e-10."""
    h = 1e-6
    for v in np.concatenate([rotvecs, [[1e-6, 0.0, 0.0], [0.0, 0.0, 0.0]]]):
        fd = np.empty((3, 3))
        for j in range(3):
            e = np.zeros(3)
            e[j] = h
            fd[:, j] = (quat.boxminus(quat.exp(v + e), quat.exp(v)) - quat.boxminus(quat.exp(v - e), quat.exp(v))) / (
                2 * h
            )
        assert np.abs(quat.right_jacobian(v) - fd).max() < 1e-8


def test_slerp_matches_scipy_along_the_shorter_arc(quaternions):
    """``slerp`` against scipy's ``Slerp`` between each pair of rotations, with ``q`` given with
    either sign (the same rotation: the arc taken must be the shorter one either way)."""
    p, q = quaternions.reshape(-1, 4)[:10], quaternions.reshape(-1, 4)[10:]
    fractions = np.array([0.0, 0.25, 0.5, 0.9, 1.0])
    for a, b in zip(p, q, strict=True):
        expected = _from_scipy(Slerp([0.0, 1.0], _scipy(np.stack([a, b])))(fractions))
        for sign in (1.0, -1.0):
            got = quat.slerp(np.broadcast_to(a, (5, 4)), np.broadcast_to(sign * b, (5, 4)), fractions)
            assert _same_rotation(got, expected) < 1e-10
