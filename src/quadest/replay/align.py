"""Put a flight log's samples onto the filter's uniform time grid.

The runner steps a filter at ``t_k = t_0 + k T`` (``T`` = ``sample_period``). PX4 logs its IMU at
about 250 Hz with jitter (3.9–4.8 ms) and dropped samples (gaps up to ~65 ms in the shipped log),
the magnetometer at its own rate, and its attitude estimate at about 100 Hz. On the grid:

- **gyro (the filter input)**: PX4's ``gyro_rad`` is the *mean* rate over the sampling interval
  that ends at its timestamp (``sensor_combined.gyro_integral_dt``). The prediction from ``t_k``
  to ``t_{k+1}`` needs the mean rate over ``(t_k, t_{k+1}]``: ``inputs[k] = (Θ(t_{k+1}) −
  Θ(t_k)) / T`` with ``Θ`` the integrated rate, piecewise linear through the samples (each
  sample's rate held over the interval that ends at it). This is exact for any ``T``, with no
  lag (taking the sample *at* ``t_k`` instead would lag by one IMU period: 0.23° at 1 rad/s);
- **accelerometer (the primary measurement at every step)**: linearly interpolated at ``t_k``;
- **magnetometer (a further sensor)**: available at step ``k`` when a new sample falls in
  ``(t_{k-1}, t_k]``; its value is the last such sample (time error below ``T``);
- **PX4's estimate (the reference)**: spherical linear interpolation (slerp, Shoemake 1985) of
  ``vehicle_attitude.q`` at ``t_k``;
- **the simulator's truth** (SITL logs): the same slerp of ``vehicle_attitude_groundtruth.q``, at
  the grid times inside its span (NaN outside).

Across a logging dropout the linear interpolation bridges the gap; :attr:`AlignedLog.gaps` counts
them (intervals longer than 1.5 T) so the docs can say how much of a log was bridged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from quadest.errors import ConfigError
from quadest.replay.ulog import FlightLog


@dataclass(frozen=True)
class AlignedLog:
    """A log on the grid ``time`` (K+1,), seconds from the log's first IMU sample.

    Attributes:
        time: (K+1,) grid times ``start + k T``.
        gyro: (K+1, 3) mean angular rate over ``(t_k, t_{k+1}]`` (the last row, which no
            prediction uses, repeats the previous).
        accel: (K+1, 3) specific force at ``t_k``.
        mag: (K+1, 3) latest magnetometer sample in ``(t_{k-1}, t_k]`` (NaN where none).
        mag_available: (K+1,) bool.
        reference_q: (K+1, 4) PX4's attitude at ``t_k``, scalar first, body FRD → earth NED.
        truth_q: (K+1, 4) the simulator's attitude at ``t_k`` (NaN outside its span), or ``None``
            when the log has no ground truth.
        gaps: number of IMU intervals longer than 1.5 T inside the grid's span.
        longest_gap: the longest IMU interval inside the span, seconds.
    """

    time: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    mag: np.ndarray
    mag_available: np.ndarray
    reference_q: np.ndarray
    gaps: int
    longest_gap: float
    truth_q: np.ndarray | None = None


def common_span(log: FlightLog) -> tuple[float, float]:
    """The first and the last time at which the IMU and the reference both have samples."""
    t0 = max(log.imu_time[0], log.accel_time[0], log.reference_time[0])
    return t0, min(log.imu_time[-1], log.accel_time[-1], log.reference_time[-1])


def align(log: FlightLog, period: float, start: float = 0.0, duration: float = float("inf")) -> AlignedLog:
    """Resample ``log`` onto ``t_k = t0 + start + k·period`` for at most ``duration`` seconds.

    ``t0`` is the first time at which both the IMU and the reference have samples; the grid ends
    at the last such time (or after ``duration``). Raises :class:`ConfigError` when the window
    holds fewer than two steps.
    """
    t0, t_last = common_span(log)
    t_end = min(t_last, t0 + start + duration)
    steps = int(np.floor((t_end - t0 - start) / period + 1e-9))
    if steps < 1:
        raise ConfigError(
            "source.start", start, f"a time inside the log (it holds {t_end - t0:.3f} s of IMU and attitude data)"
        )
    t = t0 + start + period * np.arange(steps + 1)
    gyro_mean = np.diff(_interp(t, log.imu_time, _integrated(log.imu_time, log.gyro)), axis=0) / period
    accel = _interp(t, log.accel_time, log.accel)
    mag, available = _latest_in_interval(t, log.mag_time, log.mag)
    ref = _slerp(t, log.reference_time, log.reference_q)
    truth = None
    if log.truth_q is not None:
        inside_truth = (t >= log.truth_time[0]) & (t <= log.truth_time[-1])
        truth = np.full((t.size, 4), np.nan)
        if inside_truth.any():
            truth[inside_truth] = _slerp(t[inside_truth], log.truth_time, log.truth_q)
    inside = (log.imu_time >= t[0]) & (log.imu_time <= t[-1])
    intervals = np.diff(log.imu_time[inside])
    return AlignedLog(
        time=t - t0,
        gyro=np.vstack([gyro_mean, gyro_mean[-1:]]),
        accel=accel,
        mag=mag,
        mag_available=available,
        reference_q=ref,
        gaps=int(np.sum(intervals > 1.5 * period)),
        longest_gap=float(intervals.max(initial=0.0)),
        truth_q=truth,
    )


def _slerp(t: np.ndarray, times: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``q`` (scalar first) at ``times`` slerped at ``t``, scalar part ≥ 0 (one
    sign per attitude)."""
    out = Slerp(times, Rotation.from_quat(q[:, [1, 2, 3, 0]]))(t).as_quat()[:, [3, 0, 1, 2]]
    return out * np.sign(out[:, :1] + (out[:, :1] == 0))


def _interp(t: np.ndarray, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(t, times, values[:, j]) for j in range(values.shape[1])])


def _integrated(times: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """``Θ(t_i) = Σ_{j ≤ i} ω_j (t_j − t_{j−1})``: each sample is the mean rate over the interval
    that ends at it (the first sample's interval is taken as zero)."""
    steps = np.diff(times, prepend=times[0])[:, None] * rates
    return np.cumsum(steps, axis=0)


def _latest_in_interval(t: np.ndarray, times: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each ``t_k``: the last sample with time in ``(t_{k-1}, t_k]`` (``k = 0``: at or before
    ``t_0``) and whether there is one."""
    last = np.searchsorted(times, t, side="right") - 1  # index of the last sample at or before t_k
    previous = np.concatenate([[-1], last[:-1]])
    available = last > previous
    out = np.full((len(t), values.shape[1]), np.nan)
    out[available] = values[last[available]]
    return out, available
