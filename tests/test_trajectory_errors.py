"""ATE and RPE (quadest/metrics/trajectory.py, docs/metrics.md) against constructions whose answer
is known without the code: a trajectory moved by a known SE(3) transform aligns to zero error, a
yaw-only offset aligns to zero under 4-DoF (a tilt does not), noise orthogonal to the trajectory
keeps its RMS, and a constant drift rate gives its rate times the time of the sub-trajectory.
Then, when ``QUADEST_EVO_PYTHON`` names the Python of a separate environment with ``evo`` (GPL-3.0,
never a quadest dependency), the same numbers as evo's APE and RPE on TUM files written here."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from quadest.metrics.trajectory import absolute_error, align, relative_errors

ROUND_OFF = 1e-10  # metres/radians on trajectories of a few metres, after an SVD and a few products
EVO_SCRIPT = Path(__file__).with_name("evo_trajectory_errors.py")


def _to_wxyz(rotation: Rotation) -> np.ndarray:
    return np.roll(rotation.as_quat(), 1, axis=-1)


def _reference(n=200, seed=4):
    """A 3-D trajectory (not planar) and attitudes turning with it."""
    t = np.linspace(0.0, 10.0, n)
    p = np.stack([3.0 * np.sin(0.5 * t), 2.0 * np.sin(t), 0.5 * t + 0.3 * np.cos(0.7 * t)], axis=-1)
    rng = np.random.default_rng(seed)
    euler = np.stack([0.3 * np.sin(t), 0.2 * np.cos(0.8 * t), 0.4 * t], axis=-1) + 0.01 * rng.standard_normal((n, 3))
    return p, _to_wxyz(Rotation.from_euler("xyz", euler))


def _moved(p, q, rotation: Rotation, translation):
    """The trajectory expressed in another world frame: ``p' = A p + b``, ``R' = A R``."""
    return rotation.apply(p) + translation, _to_wxyz(rotation * Rotation.from_quat(np.roll(q, -1, axis=-1)))


def test_a_trajectory_moved_by_a_known_se3_transform_aligns_to_zero_error():
    p, q = _reference()
    A = Rotation.from_rotvec([0.4, -1.1, 2.0])
    p_est, q_est = _moved(p, q, A, np.array([5.0, -2.0, 1.0]))
    ate = absolute_error(p_est, q_est, p, q, "se3")
    np.testing.assert_allclose(ate.alignment.rotation, A.inv().as_matrix(), atol=ROUND_OFF)
    assert ate.position_rmse < ROUND_OFF and ate.rotation_rmse < ROUND_OFF


def test_a_planar_trajectory_aligns_by_a_rotation_not_a_reflection():
    """Points in a plane fit a reflection as well as a rotation; Umeyama's S (eq. 43) keeps det R = +1,
    so the attitudes align too."""
    p, q = _reference()
    p[:, 2] = 1.0
    A = Rotation.from_rotvec([0.0, 0.0, 2.5]) * Rotation.from_rotvec([0.3, 0.0, 0.0])
    p_est, q_est = _moved(p, q, A, np.array([1.0, 2.0, 3.0]))
    ate = absolute_error(p_est, q_est, p, q, "se3")
    assert np.linalg.det(ate.alignment.rotation) == pytest.approx(1.0, abs=ROUND_OFF)
    assert ate.position_rmse < ROUND_OFF and ate.rotation_rmse < ROUND_OFF


def test_a_mirrored_trajectory_is_not_aligned_by_a_reflection():
    """The orthogonal matrix that fits a mirror image best is the mirror itself (error 0, det −1);
    the alignment is restricted to rotations (S of eq. 43), which must leave an error: Umeyama's
    minimum ``var_x + var_y − 2 tr(D S)`` with ``S = diag(1, 1, −1)``."""
    p, q = _reference()
    mirrored = p * np.array([1.0, 1.0, -1.0])
    a = align(mirrored, p, "se3")
    assert np.linalg.det(a.rotation) == pytest.approx(1.0, abs=ROUND_OFF)
    xc, yc = mirrored - mirrored.mean(axis=0), p - p.mean(axis=0)
    d = np.linalg.svd(yc.T @ xc / len(p), compute_uv=False)
    least = np.mean(np.sum(xc**2, axis=-1)) + np.mean(np.sum(yc**2, axis=-1)) - 2.0 * (d[0] + d[1] - d[2])
    ate = absolute_error(mirrored, q, p, q, "se3")
    assert ate.position_rmse == pytest.approx(np.sqrt(least), rel=1e-9) and ate.position_rmse > 0.1


def test_a_yaw_offset_aligns_to_zero_under_4dof_and_a_tilt_does_not():
    p, q = _reference()
    yaw = Rotation.from_rotvec([0.0, 0.0, -2.2])
    p_est, q_est = _moved(p, q, yaw, np.array([0.5, 4.0, -1.0]))
    ate = absolute_error(p_est, q_est, p, q, "4dof")
    assert ate.position_rmse < ROUND_OFF and ate.rotation_rmse < ROUND_OFF
    tilt = Rotation.from_rotvec([0.1, 0.0, 0.0])
    p_tilted, q_tilted = _moved(p, q, tilt, np.zeros(3))
    tilted = absolute_error(p_tilted, q_tilted, p, q, "4dof")
    # a yaw-only R leaves an angle of at least the tilt: tr(Rz(ψ) Rx(α)) = (1 + cos ψ)(1 + cos α) − 1
    assert tilted.rotation_rmse >= 0.1 - ROUND_OFF
    np.testing.assert_array_equal(tilted.alignment.rotation[2], [0.0, 0.0, 1.0])
    assert absolute_error(p_tilted, q_tilted, p, q, "se3").rotation_rmse < ROUND_OFF


@pytest.mark.parametrize("kind", ["se3", "4dof"])
def test_noise_orthogonal_to_the_trajectory_keeps_its_rms(kind):
    """Noise with zero mean and no correlation with the centred reference leaves the alignment at
    the identity (the cross-covariance is the reference's own, symmetric), so the ATE is the
    noise's RMS exactly."""
    p, q = _reference()
    rng = np.random.default_rng(7)
    basis = np.column_stack([np.ones(len(p)), p - p.mean(axis=0)])
    noise = rng.standard_normal(p.shape)
    noise -= basis @ np.linalg.lstsq(basis, noise, rcond=None)[0]
    rms = 0.37
    noise *= rms / np.sqrt(np.mean(np.sum(noise**2, axis=-1)))
    ate = absolute_error(p + noise, q, p, q, kind)
    assert ate.position_rmse == pytest.approx(rms, rel=1e-12)
    np.testing.assert_allclose(ate.alignment.rotation, np.eye(3), atol=ROUND_OFF)


def _straight_line(n=301, speed=2.0, period=0.01):
    t = period * np.arange(n)
    p = np.stack([speed * t, np.zeros(n), np.ones(n)], axis=-1)
    q = np.broadcast_to(_to_wxyz(Rotation.from_rotvec([0.2, -0.1, 0.7])), (n, 4))
    return t, p, q


def test_rpe_of_a_constant_position_drift_is_the_drift_rate_times_the_time_of_d():
    """Flying at 2 m/s with a position drift of 0.3 m/s: every pair d metres apart is d/2 s apart,
    and its translation error is 0.3 · d/2 m, whatever the (constant) attitude."""
    t, p, q = _straight_line()
    drift = np.array([0.1, -0.2, 0.2])  # |drift| = 0.3 m/s
    for rpe, d in zip(
        relative_errors(p + t[:, None] * drift, q, p, q, [0.5, 2.0], rel_tol=0.01), [0.5, 2.0], strict=True
    ):
        steps = round(d / 0.02)
        assert len(rpe.pairs) == len(t) - steps and np.all(rpe.pairs[:, 1] - rpe.pairs[:, 0] == steps)
        np.testing.assert_allclose(rpe.translation, 0.3 * d / 2.0, rtol=1e-9)
        assert np.all(rpe.rotation < ROUND_OFF)


def test_rpe_of_a_constant_rotation_drift_is_the_rate_times_the_time_of_d():
    t, p, q = _straight_line()
    rate = np.array([0.0, 0.03, -0.04])  # 0.05 rad/s about a fixed body axis
    q_est = np.stack(
        [
            (Rotation.from_quat(np.roll(qi, -1)) * Rotation.from_rotvec(ti * rate)).as_quat()
            for qi, ti in zip(q, t, strict=True)
        ]
    )
    (rpe,) = relative_errors(p, np.roll(q_est, 1, axis=-1), p, q, [1.0], rel_tol=0.01)
    np.testing.assert_allclose(rpe.rotation, 0.05 * 1.0 / 2.0, rtol=1e-9)


def test_an_unknown_alignment_is_refused():
    p, _ = _reference()
    with pytest.raises(ValueError, match="alignment must be one of"):
        align(p, p, "sim3")


def _write_tum(path: Path, t, p, q) -> None:
    rows = [
        f"{ti:.9f} " + " ".join(repr(float(v)) for v in (*pi, *qi[1:], qi[0]))
        for ti, pi, qi in zip(t, p, q, strict=True)
    ]
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.integration
def test_ape_and_rpe_equal_evos(tmp_path):
    """evo 1.x (``metrics.APE`` after ``align`` without scale; ``metrics.RPE`` with ``delta`` in
    metres, all pairs chosen along the reference, relative tolerance 0.1) on the same TUM files."""
    python = os.environ.get("QUADEST_EVO_PYTHON")
    if not python or not Path(python).exists():
        pytest.skip(
            "the check against evo needs its own environment: set QUADEST_EVO_PYTHON to its Python (docs/metrics.md)"
        )
    p, q = _reference()
    t = 0.05 * np.arange(len(p))
    rng = np.random.default_rng(11)
    drift = np.cumsum(0.02 * rng.standard_normal(p.shape), axis=0)
    wobble = Rotation.from_rotvec(np.cumsum(0.003 * rng.standard_normal(p.shape), axis=0))
    A = Rotation.from_rotvec([0.2, 0.1, 1.3])
    p_est, q_est = _moved(
        p + drift, _to_wxyz(Rotation.from_quat(np.roll(q, -1, axis=-1)) * wobble), A, np.array([1.0, -3.0, 0.5])
    )
    _write_tum(tmp_path / "reference.txt", t, p, q)
    _write_tum(tmp_path / "estimate.txt", t, p_est, q_est)
    distances = [1.0, 4.0]
    files = [str(tmp_path / "reference.txt"), str(tmp_path / "estimate.txt")]
    done = subprocess.run(
        [python, str(EVO_SCRIPT), *files, *map(str, distances)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    evo = json.loads(done.stdout.strip().splitlines()[-1])
    ours = absolute_error(p_est, q_est, p, q, "se3")
    print(f"evo {evo['evo']}: APE {ours.position_rmse:.12f} m (evo {evo['ape_translation_rmse']:.12f}), "
          f"{ours.rotation_rmse:.12f} rad (evo {evo['ape_rotation_rmse']:.12f})")  # fmt: skip
    assert ours.position_rmse == pytest.approx(evo["ape_translation_rmse"], rel=1e-9)
    assert ours.rotation_rmse == pytest.approx(evo["ape_rotation_rmse"], rel=1e-9)
    for rpe, theirs in zip(relative_errors(p_est, q_est, p, q, distances, rel_tol=0.1), evo["rpe"], strict=True):
        rms = [
            np.sqrt(np.mean(np.square(e)))
            for e in (rpe.translation, theirs["translation"], rpe.rotation, theirs["rotation"])
        ]
        print(f"RPE at {rpe.distance:g} m: {len(rpe.pairs)} pairs (evo {len(theirs['delta_ids'])}), "
              f"RMS {rms[0]:.12f} m (evo {rms[1]:.12f}), {rms[2]:.12f} rad (evo {rms[3]:.12f}), largest difference "
              f"{np.max(np.abs(rpe.translation - theirs['translation'])):.1e} m, "
              f"{np.max(np.abs(rpe.rotation - theirs['rotation'])):.1e} rad")  # fmt: skip
        assert rpe.pairs[:, 1].tolist() == theirs["delta_ids"]
        np.testing.assert_allclose(rpe.translation, theirs["translation"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(rpe.rotation, theirs["rotation"], rtol=1e-9, atol=1e-12)


def _ins_series(p, q):
    """A job's saved series with the INS state ``[q, p, v, b_g, b_a]`` (zeros past p)."""
    x = np.concatenate([q, p, np.zeros((len(p), 9))], axis=-1)
    return x[None]


@pytest.mark.integration
def test_the_command_reads_a_jobs_series_and_writes_trajectory_errors_csv(tmp_path):
    """An estimate that is the truth moved by a yaw and a translation has no error after either
    alignment and no relative error; a diverged run (NaN) is left out; a truth that is not the INS
    state is refused with exit status 2."""
    p, q = _reference()
    yaw = Rotation.from_rotvec([0.0, 0.0, 0.8])
    p_moved, q_moved = _moved(p, q, yaw, np.array([2.0, -1.0, 0.5]))
    truth = np.concatenate([_ins_series(p, q)] * 2)
    estimate = np.concatenate([_ins_series(p_moved, q_moved), np.full((1, len(p), 16), np.nan)])
    np.savez(tmp_path / "timeseries.npz", time=np.arange(len(p)) * 0.05, truth=truth, **{"mekf/estimate": estimate})
    done = subprocess.run(
        [sys.executable, "-m", "quadest.evaluation.trajectory_errors", str(tmp_path), "--distances", "1", "4"],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    table = pd.read_csv(tmp_path / "trajectory_errors.csv")
    assert list(table["measure"]) == ["ate_se3", "ate_4dof", "rpe", "rpe"] and set(table["run"]) == {0}
    assert list(table["distance_m"].iloc[2:]) == [1.0, 4.0] and (table["pairs"] > 0).all()
    assert (table["position_m"] < ROUND_OFF).all() and (table["rotation_deg"] < np.degrees(ROUND_OFF)).all()
    np.savez(
        tmp_path / "timeseries.npz",
        time=np.arange(3.0),
        truth=np.zeros((1, 3, 10)),
        **{"mekf/estimate": np.zeros((1, 3, 10))},
    )
    refused = subprocess.run(
        [sys.executable, "-m", "quadest.evaluation.trajectory_errors", str(tmp_path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1 and "model=ins" in refused.stderr
