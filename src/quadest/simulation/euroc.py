"""EuRoC-layout folders as recordings (:class:`~quadest.simulation.recording.Recording`): the IMU
in, the motion-capture reference out, on the IMU's time stamps (docs/models.md, "Data from a file").

The layout of the EuRoC MAV datasets (Burri et al. 2016, "The EuRoC micro aerial vehicle
datasets", IJRR 35(10)) and of the datasets that copy it, under the given folder:

- ``mav0/imu0/data.csv``: ``#timestamp [ns], w_RS_S_x, w_RS_S_y, w_RS_S_z [rad s^-1],
  a_RS_S_x, a_RS_S_y, a_RS_S_z [m s^-2]``, the gyro and the accelerometer in the IMU frame S;
- ``mav0/state_groundtruth_estimate0/data.csv``: ``#timestamp, p_RS_R (3) [m], q_RS (w, x, y, z),
  v_RS_R (3) [m s^-1], b_w_RS_S (3) [rad s^-1], b_a_RS_S (3) [m s^-2]``, the pose of S in the
  reference frame R, its velocity in R and the IMU's biases (measured = true + bias, the
  convention of our filters' ``b_g``, ``b_a``).

Columns are found by name (units in brackets and a leading ``#`` are ignored); time stamps are read
as integers (nanoseconds since 1970 do not fit a float's 53 bits).

**Frames.** EuRoC's R is a z-up world frame with gravity along −z; our earth frame (docs/ins.md,
:mod:`quadest.models.ins`) is z up with ``g_e = [0, 0, −g]``, and neither model uses north unless a
magnetometer is simulated. The conversion is therefore the identity rotation
:data:`EARTH_FROM_EUROC`, applied explicitly: ``p_E = C p_R``, ``v_E = C v_R``,
``q_ES = q(C) ⊗ q_RS``; the body frame of the filters is the IMU frame S (the reference is S's
pose), and the biases stay in S. Both quaternion conventions are Hamilton, scalar first, body → world.

**Time.** The reference is interpolated at each IMU time stamp inside its span: linearly for
position, velocity and biases, by :func:`~quadest.numerics.quaternion.slerp` for the attitude. IMU
samples before the first or after the last reference sample are dropped (counted in the
recording's ``notes``: ``imu_dropped_before``, ``imu_dropped_after``, with the longest reference
gap bridged by interpolation, ``reference_largest_gap_s``). Times count in seconds from the first
kept IMU sample. The IMU samples are returned as measured (instantaneous); a model that expects
the mean over the following step converts them (:func:`quadest.simulation.imu.interval_means`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadest.numerics import quaternion as quat
from quadest.simulation.recording import Recording

IMU_CSV = Path("mav0", "imu0", "data.csv")
REFERENCE_CSV = Path("mav0", "state_groundtruth_estimate0", "data.csv")
IMU_COLUMNS = ("timestamp", "w_RS_S_x", "w_RS_S_y", "w_RS_S_z", "a_RS_S_x", "a_RS_S_y", "a_RS_S_z")
REFERENCE_COLUMNS = (
    "timestamp", "p_RS_R_x", "p_RS_R_y", "p_RS_R_z", "q_RS_w", "q_RS_x", "q_RS_y", "q_RS_z",
    "v_RS_R_x", "v_RS_R_y", "v_RS_R_z", "b_w_RS_S_x", "b_w_RS_S_y", "b_w_RS_S_z",
    "b_a_RS_S_x", "b_a_RS_S_y", "b_a_RS_S_z",
)  # fmt: skip
EARTH_FROM_EUROC = np.array([1.0, 0.0, 0.0, 0.0])
"""The rotation from EuRoC's R frame to our earth frame (a quaternion): both are z up with gravity
along −z, so it is the identity."""
TRUTH_NAMES = ("qw", "qx", "qy", "qz", "x", "y", "z", "vx", "vy", "vz",
               "bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z")  # fmt: skip
"""The truth's columns: the INS state (:data:`quadest.models.ins.STATE_NAMES`)."""


def _header(path: Path, required: tuple[str, ...]) -> list[int]:
    """The column index of each of ``required`` in the CSV ``path`` (names without units or ``#``)."""
    if not path.is_file():
        raise ValueError(f"{path} is missing (an EuRoC folder has {IMU_CSV} and {REFERENCE_CSV})")
    with path.open() as fh:
        first = fh.readline()
    names = [cell.split("[")[0].strip().lstrip("#").strip() for cell in first.split(",")]
    missing = [name for name in required if name not in names]
    if missing:
        raise ValueError(f"{path}: column(s) {', '.join(missing)} missing from the header (found {', '.join(names)})")
    return [names.index(name) for name in required]


def check_euroc_folder(folder: Path) -> None:
    """Both CSV files exist and name every column they need (headers only: no data read).

    Raises:
        ValueError: one line naming the missing file or columns.
    """
    _header(folder / IMU_CSV, IMU_COLUMNS)
    _header(folder / REFERENCE_CSV, REFERENCE_COLUMNS)


def _table(path: Path, required: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps, values)``: the integer time stamps (N,) and the other required columns (N, d)."""
    columns = _header(path, required)
    try:
        stamps = np.loadtxt(path, delimiter=",", skiprows=1, usecols=columns[0], dtype=np.int64, ndmin=1)
        values = np.loadtxt(path, delimiter=",", skiprows=1, usecols=columns[1:], dtype=float, ndmin=2)
    except ValueError as exc:
        raise ValueError(f"{path}: not a table of numbers ({exc})") from None
    if stamps.size < 2 or np.any(np.diff(stamps) <= 0):
        raise ValueError(f"{path}: needs at least two rows with strictly increasing time stamps")
    return stamps, values


def interpolate_reference(ref_stamps: np.ndarray, reference: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """The reference rows (N, 16: p, q, v, b_w, b_a as in the CSV) at ``stamps``, every one inside
    ``[ref_stamps[0], ref_stamps[-1]]``: linear in p, v and the biases, slerp in q (module docstring)."""
    i = np.clip(np.searchsorted(ref_stamps, stamps, side="right") - 1, 0, ref_stamps.size - 2)
    fraction = (stamps - ref_stamps[i]).astype(float) / (ref_stamps[i + 1] - ref_stamps[i]).astype(float)
    lo, hi = reference[i], reference[i + 1]
    out = lo + fraction[:, None] * (hi - lo)
    q_lo, q_hi = quat.normalize(lo[:, 3:7]), quat.normalize(hi[:, 3:7])
    out[:, 3:7] = quat.slerp(q_lo, q_hi, fraction)
    return out


def read_euroc(folder: str | Path) -> Recording:
    """The EuRoC-layout ``folder`` as one recording: ``time`` (K,) s from the first kept IMU sample,
    ``inputs`` (K, 6) the IMU ``[ω̃, f̃]`` as measured, ``truth`` (K, 16) ``[q, p, v, b_g, b_a]`` in
    our earth frame, ``measurements`` (K, 0), and ``notes`` on what was dropped (module docstring).

    Raises:
        ValueError: a missing file or column, a table that is not numbers, or no IMU sample inside
            the reference's span; one line naming the file.
    """
    folder = Path(folder)
    imu_stamps, imu = _table(folder / IMU_CSV, IMU_COLUMNS)
    ref_stamps, reference = _table(folder / REFERENCE_CSV, REFERENCE_COLUMNS)
    inside = (imu_stamps >= ref_stamps[0]) & (imu_stamps <= ref_stamps[-1])
    if np.count_nonzero(inside) < 2:
        raise ValueError(f"{folder}: fewer than two IMU samples inside the reference's time span")
    stamps = imu_stamps[inside]
    ref = interpolate_reference(ref_stamps, reference, stamps)
    covered = (ref_stamps >= stamps[0]) & (ref_stamps <= stamps[-1])
    gaps = np.diff(ref_stamps[covered]) if np.count_nonzero(covered) > 1 else np.zeros(1, dtype=np.int64)
    truth = np.concatenate(
        [
            quat.multiply(EARTH_FROM_EUROC, ref[:, 3:7]),
            quat.rotate(EARTH_FROM_EUROC, ref[:, 0:3]),
            quat.rotate(EARTH_FROM_EUROC, ref[:, 7:10]),
            ref[:, 10:16],
        ],
        axis=-1,
    )
    first_kept = int(np.argmax(inside))
    notes = {
        "imu_dropped_before": first_kept,
        "imu_dropped_after": int(imu_stamps.size - first_kept - stamps.size),
        "reference_largest_gap_s": float(gaps.max()) * 1e-9,
    }
    time = (stamps - stamps[0]).astype(float) * 1e-9
    return Recording(time, np.zeros((stamps.size, 0)), truth, imu[inside], notes)
