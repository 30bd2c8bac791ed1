"""Small EuRoC-layout folders for the tests, written from an analytic motion.

The motion is built here independently of quadest's models: position and ZYX Euler angles are
closed-form functions of time, the body rate is the Euler-rate kinematics and the specific force
``f_b = Rᵀ (a − g_e)`` with ``R`` from scipy (scalar-last quaternions reordered), ``g_e = [0, 0, −g]``
in a z-up world. The IMU reads ``true + bias`` with constant biases, as EuRoC's convention.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

IMU_HEADER = (
    "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]"
)
REFERENCE_HEADER = (
    "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
    "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], "
    "b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]"
)
START_NS = 1_403_636_579_758_555_392  # a EuRoC-like stamp: beyond a float's 53 bits
GRAVITY = 9.81
GYRO_BIAS = np.array([0.01, -0.02, 0.005])
ACCEL_BIAS = np.array([0.1, -0.05, 0.2])


def motion(t: np.ndarray) -> dict[str, np.ndarray]:
    """Position, velocity, acceleration (N, 3), quaternion ``[w, x, y, z]`` (N, 4) body → world,
    body rate and specific force (N, 3) of the analytic flight at times ``t`` (s)."""
    w = 0.8
    s1, c1, s2, c2 = np.sin(w * t), np.cos(w * t), np.sin(2 * w * t), np.cos(2 * w * t)
    p = np.stack([1.5 * s1, 1.0 * s2, 1.0 + 0.3 * s1], axis=-1)
    v = np.stack([1.5 * w * c1, 2.0 * w * c2, 0.3 * w * c1], axis=-1)
    a = np.stack([-1.5 * w**2 * s1, -4.0 * w**2 * s2, -0.3 * w**2 * s1], axis=-1)
    roll, droll = 0.2 * np.sin(1.1 * t), 0.22 * np.cos(1.1 * t)
    pitch, dpitch = 0.15 * np.sin(0.9 * t + 0.3), 0.135 * np.cos(0.9 * t + 0.3)
    yaw, dyaw = 0.4 * t + 0.5, 0.4 * np.ones_like(t)
    rate = np.stack(
        [
            droll - dyaw * np.sin(pitch),
            dpitch * np.cos(roll) + dyaw * np.cos(pitch) * np.sin(roll),
            -dpitch * np.sin(roll) + dyaw * np.cos(pitch) * np.cos(roll),
        ],
        axis=-1,
    )
    rotation = Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], axis=-1))
    force = rotation.inv().apply(a + np.array([0.0, 0.0, GRAVITY]))
    q = np.roll(rotation.as_quat(), 1, axis=-1)
    return {"p": p, "v": v, "a": a, "q": q, "rate": rate, "force": force}


def reference_rows(t: np.ndarray) -> np.ndarray:
    """The reference CSV's 16 value columns ``p, q (w first), v, b_w, b_a`` at times ``t``."""
    m = motion(t)
    biases = np.broadcast_to(np.concatenate([GYRO_BIAS, ACCEL_BIAS]), (t.size, 6))
    return np.concatenate([m["p"], m["q"], m["v"], biases], axis=-1)


def imu_rows(t: np.ndarray) -> np.ndarray:
    """The IMU CSV's 6 value columns ``ω̃, f̃`` (true + bias) at times ``t``."""
    m = motion(t)
    return np.concatenate([m["rate"] + GYRO_BIAS, m["force"] + ACCEL_BIAS], axis=-1)


def _write(path: Path, header: str, stamps: np.ndarray, values: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [header] + [f"{s}," + ",".join(repr(float(v)) for v in row) for s, row in zip(stamps, values, strict=True)]
    path.write_text("\n".join(lines) + "\n")


def write_euroc(
    folder: Path,
    imu_stamps: np.ndarray,
    imu: np.ndarray,
    reference_stamps: np.ndarray,
    reference: np.ndarray,
    imu_header: str = IMU_HEADER,
    reference_header: str = REFERENCE_HEADER,
) -> Path:
    """Write ``folder/mav0/imu0/data.csv`` and ``folder/mav0/state_groundtruth_estimate0/data.csv``."""
    _write(folder / "mav0" / "imu0" / "data.csv", imu_header, imu_stamps, imu)
    _write(folder / "mav0" / "state_groundtruth_estimate0" / "data.csv", reference_header, reference_stamps, reference)
    return folder


def stamps(period_ns: int, count: int, first: int = 0) -> np.ndarray:
    """``count`` integer stamps (ns) every ``period_ns`` from sample ``first`` on."""
    return START_NS + period_ns * np.arange(first, first + count, dtype=np.int64)


def seconds(stamp: np.ndarray) -> np.ndarray:
    """Stamps as seconds since :data:`START_NS` (exact integer difference first)."""
    return (stamp - START_NS).astype(float) * 1e-9


def write_flight(folder: Path, period_ns: int, duration: float) -> Path:
    """The analytic flight of ``duration`` s, IMU and reference on the same stamps."""
    s = stamps(period_ns, round(duration * 1e9 / period_ns) + 1)
    return write_euroc(folder, s, imu_rows(seconds(s)), s, reference_rows(seconds(s)))
