"""The Monte Carlo data of a log replay: one run, the log's sensors, PX4's estimate as reference.

A replay is one "run" (B = 1) of :class:`~quadest.models.attitude.AttitudeFilterModel` on the
aligned log (:mod:`quadest.replay.align`), in PX4's frames (body FRD, earth NED):

- input ``u = [ω_m, a_e = 0]``: the gyro; the vehicle's acceleration is unknown (no aiding), so
  ``R_acc`` carries ``model.acceleration_std²`` on top of the accelerometer's white noise;
- primary measurement: the accelerometer; further sensor ``"mag"``: the magnetometer in µT
  (PX4 logs gauss; ×100) at its own samples;
- gravity ``g_e = [0, 0, g]`` (NED: down) with ``g`` the median norm of the log's accelerometer
  (a gravity-magnitude calibration: the accelerometer's residual scale error, 9.70 against
  9.81 m/s² in the shipped log, would otherwise be explained by the z bias alone and tilt the
  estimate by the scale error times the tilt, 0.07° at the shipped log's 7° of pitch); earth
  field ``m_e``: the log's median
  magnetometer vector levelled by the accelerometer's tilt at each magnetometer sample, north
  component along x (magnetic north; PX4's ``attitude_estimator_q`` uses magnetic heading too
  when the log has no GPS for the declination). It is a site constant, what a World Magnetic
  Model lookup gives when the position is known; the log has none, so it comes from the data;
- noise from the configured sensor (``sensor=consumer`` is the MPU-6000 class of the PX4 board)
  and the model's magnetometer, process-noise and initial-uncertainty settings, with the same
  formulas as ``model=attitude`` (:mod:`quadest.simulation.attitude_data`); the sensor's deterministic
  errors are not modelled (PX4 applies its own calibration before logging);
- initial estimate from the first samples alone (roll and pitch from the accelerometer, yaw from
  the magnetometer; zero biases), never from PX4's estimate;
- ``truth``: PX4's attitude as a filter state with zero biases (PX4 does not log its bias
  estimates). It is a *reference*, labelled ``reference: PX4 onboard
  estimate``; only its attitude is compared (:mod:`quadest.app.replay_job`);
- beside them (:class:`ReplayData`): the simulator's attitude where the log has one (SITL's
  ``vehicle_attitude_groundtruth``), the truth both PX4's estimate and ours are scored against, and
  the log's magnetic declination (:mod:`quadest.replay.declination`), which turns our filters'
  magnetic yaw to PX4's true north before any comparison.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quadest.config.notices import warn
from quadest.config.ranges import require_non_negative
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.attitude import AttitudeFilterModel
from quadest.models.quadrotor_config import triad_spec
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.streams import run_seed_sequences
from quadest.numerics import quaternion as quat
from quadest.replay.align import AlignedLog, align, common_span
from quadest.replay.declination import Declination, log_declination
from quadest.replay.ulog import incomplete_tail, read_flight_log
from quadest.sensors.mimu import TriadSpec
from quadest.sensors.record import SensorRecord

REFERENCE = "PX4 onboard estimate"
GAUSS_TO_MICROTESLA = 100.0
_PACKAGE = Path(__file__).resolve().parents[1]


PX4_ROW = "px4"
"""PX4's own estimate as a row of ``truth_errors.csv``: no estimator of a replay may take this label."""


def shipped_log() -> Path:
    """The flight log shipped with quadest: the wheel's copy first, the repository's second."""
    for candidate in (_PACKAGE / "data" / "px4", _PACKAGE.parents[1] / "data" / "px4"):
        if (candidate / "sample.ulg").is_file():
            return candidate / "sample.ulg"
    raise FileNotFoundError(f"the shipped PX4 log is missing from {_PACKAGE / 'data/px4'}; reinstall quadest")


@dataclass
class ReplayData(MonteCarloData):
    """A replay's Monte Carlo data and what the report needs besides it.

    Attributes:
        ground_truth: (K+1, 4) the simulator's body→NED quaternion on the grid (NaN outside its
            span), or ``None``: the log has no ``vehicle_attitude_groundtruth``.
        position_truth: whether the log has ``vehicle_local_position_groundtruth``.
        declination: applied to our filters' yaw before every comparison.
    """

    ground_truth: np.ndarray | None = None
    position_truth: bool = False
    declination: Declination = field(default_factory=lambda: log_declination({}, ()))


@dataclass
class SourceConf:
    """The ``source`` node: a recorded flight log replayed instead of the simulation (docs/replay.md;
    null: simulate). ``path`` null is the shipped PX4 log; ``start`` skips seconds of the log;
    differences to the log's reference count from ``warmup`` seconds after the start."""

    name: str = "px4"
    path: str | None = None
    start: float = 0.0
    warmup: float = 5.0


def log_path(path: Any) -> Path:
    """The log of ``source.path`` ``path``, or the shipped log when it is null."""
    return shipped_log() if path is None else Path(str(path)).expanduser()


def validate_replay(settings: DataSettings, saved_runs: int) -> None:
    """Checks of a replay's settings (``saved_runs``: ``output.saved_runs``), before any work
    (called by :func:`quadest.app.validate.validate`)."""
    source = settings.source
    if settings.model.name != "attitude":
        raise ConfigError("model.name", settings.model.name, "'attitude' for a log replay (source.name=px4)")
    if settings.runs != 1:
        raise ConfigError("runs", settings.runs, "1 for a log replay (a log is one run)")
    if saved_runs < 1:
        raise ConfigError("output.saved_runs", saved_runs, ">= 1 (a replay compares the saved estimates)")
    if source.name != "px4":
        raise ConfigError("source.name", source.name, "'px4' (a PX4 ULog file), or source=null to simulate")
    require_non_negative("source.start", source.start)
    require_non_negative("source.warmup", source.warmup)
    path = log_path(source.path)
    if not path.is_file():
        raise ConfigError("source.path", str(source.path), "an existing PX4 ULog file (.ulg), or null: the shipped log")
    check_log_length(path, settings)


def check_log_length(path: Path, settings: DataSettings) -> None:
    """Refuse a ``source.warmup`` that reaches past the end of the replayed window (nothing would be
    compared), and name in a warning a log cut mid-message (:func:`~quadest.replay.ulog.incomplete_tail`)
    or one shorter than the ``duration`` asked for."""
    source = settings.source
    t0, t_end = common_span(read_flight_log(path))
    held = t_end - t0 - source.start  # seconds of IMU and attitude data after source.start
    if not held > settings.sample_period:
        raise ConfigError("source.start", source.start, f"a time inside the log ({path.name} holds {t_end - t0:.3f} s "
                          "of IMU and attitude data)")  # fmt: skip
    window = min(held, settings.duration)
    if not source.warmup < window:
        raise ConfigError("source.warmup", source.warmup, f"less than the {window:.3f} s replayed ({path.name} holds "
                          f"{t_end - t0:.3f} s of IMU and attitude data, source.start={source.start:g})")  # fmt: skip
    cut = incomplete_tail(path)
    if cut:
        warn(f"{path} ends in {cut} bytes of an incomplete message: the log was truncated; it holds "
             f"{t_end - t0:.3f} s of IMU and attitude data, of which {window:.3f} s are replayed")  # fmt: skip
    if math.isfinite(settings.duration) and held < settings.duration:
        warn(f"{path} holds {held:.3f} s after source.start={source.start:g}, less than "
             f"duration={settings.duration:g}; replaying to its end")  # fmt: skip


def tilt(accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch (rad) of a body FRD whose accelerometer reads ``accel`` (..., 3) at rest in
    NED: ``f = R(q)ᵀ [0, 0, −g]`` gives ``φ = atan2(−f_y, −f_z)``, ``θ = atan2(f_x, √(f_y² + f_z²))``."""
    roll = np.arctan2(-accel[..., 1], -accel[..., 2])
    pitch = np.arctan2(accel[..., 0], np.hypot(accel[..., 1], accel[..., 2]))
    return roll, pitch


def _levelled(accel: np.ndarray, mag: np.ndarray) -> np.ndarray:
    """The magnetometer vectors (..., 3) rotated by the accelerometer's tilt alone (yaw 0)."""
    roll, pitch = tilt(accel)
    return quat.rotate(quat.from_euler(np.stack([roll, pitch, np.zeros_like(roll)], axis=-1)), mag)


def earth_field(aligned: AlignedLog) -> np.ndarray:
    """``m_e = [median |m_h|, 0, median m_d]`` (the log's units) over the magnetometer samples,
    each levelled by the accelerometer's tilt at that step."""
    ok = aligned.mag_available
    level = _levelled(aligned.accel[ok], aligned.mag[ok])
    return np.array([np.median(np.hypot(level[:, 0], level[:, 1])), 0.0, np.median(level[:, 2])])


def initial_state(aligned: AlignedLog) -> np.ndarray:
    """x0 (10,): roll and pitch from the first accelerometer sample, yaw from the first
    magnetometer sample levelled by them (``ψ = −atan2(m_y, m_x)``), zero biases."""
    first_mag = int(np.flatnonzero(aligned.mag_available)[0])
    roll, pitch = tilt(aligned.accel[0])
    level = _levelled(aligned.accel[0], aligned.mag[first_mag])
    yaw = -np.arctan2(level[1], level[0])
    return AttitudeFilterModel.truth_state(np.array([roll, pitch, yaw]), np.zeros(3), np.zeros(3))


def replay_noise(
    settings: DataSettings, T: float, mag_period: float, duration: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``Q`` (9, 9) per step, ``R_acc``, ``R_mag`` (3, 3) and ``P0`` (9, 9), by the formulas of
    ``model=attitude`` without aiding (module docstring of :mod:`quadest.simulation.attitude_data`)."""
    m, scale = settings.model, float(settings.sensor.error_scale)
    accel, gyro = triad_spec(settings.sensor.accel, scale), triad_spec(settings.sensor.gyro, scale)
    mag = TriadSpec(
        white_noise=float(m.magnetometer.white_noise), bias_random_walk=float(m.magnetometer.bias_random_walk)
    )
    inflation = float(m.attitude_process_noise.inflation)
    q_att = gyro.white_noise**2 * T + float(m.attitude_process_noise.attitude) ** 2
    Q = inflation * np.diag([q_att] * 3 + [gyro.bias_random_walk**2 * T] * 3 + [accel.bias_random_walk**2 * T] * 3)
    noise = float(m.measurement_noise_inflation)
    R_acc = noise * (accel.white_noise_std(T) ** 2 + float(m.acceleration_std) ** 2) * np.eye(3)
    R_mag = noise * (mag.white_noise_std(mag_period) ** 2 + mag.bias_random_walk**2 * duration / 2.0) * np.eye(3)
    s0 = m.attitude_initial_std
    P0 = np.diag([float(s0.attitude) ** 2] * 3 + [float(s0.gyro_bias) ** 2] * 3 + [float(s0.accel_bias) ** 2] * 3)
    return Q, R_acc, R_mag, P0


def build_replay_data(settings: DataSettings) -> ReplayData:
    """Read ``source.path``, align it to ``sample_period`` and bind the attitude model to it
    (``settings`` validated, :func:`validate_replay` included)."""
    path = log_path(settings.source.path)
    log = read_flight_log(path)
    T = float(settings.sample_period)
    aligned = align(log, T, float(settings.source.start), float(settings.duration))
    aligned_uT = dataclasses.replace(aligned, mag=aligned.mag * GAUSS_TO_MICROTESLA)
    mag_period = float(np.median(np.diff(log.mag_time)))
    Q, R_acc, R_mag, P0 = replay_noise(settings, T, mag_period, float(aligned.time[-1] - aligned.time[0]))
    g_e = np.array([0.0, 0.0, float(np.median(np.linalg.norm(aligned.accel, axis=1)))])
    model = AttitudeFilterModel(T, g_e, earth_field(aligned_uT), Q, R_acc, R_mag)
    K1 = aligned.time.size
    reference = np.concatenate([aligned.reference_q, np.zeros((K1, 6))], axis=-1)  # [q, b_g = 0, b_a = 0]
    labels = {
        "model": "attitude", "source": "px4", "log": path.name, "layout": log.layout, "reference": REFERENCE,
        "warmup": float(settings.source.warmup), "bridged_gaps": aligned.gaps, "longest_gap": aligned.longest_gap,
    }  # fmt: skip
    return ReplayData(
        model=model,
        time=aligned.time,
        truth=reference[None],
        companion_truth=np.zeros((1, K1, 0)),
        inputs=np.concatenate([aligned.gyro, np.zeros((K1, 3))], axis=-1)[None],
        measurements=aligned.accel[None],
        x0=initial_state(aligned_uT)[None],
        P0=P0,
        companion0=np.zeros((1, 0)),
        estimator_seeds=run_seed_sequences(int(settings.seed), 1)["estimator"],
        labels=labels,
        sensors={"mag": SensorRecord(np.nan_to_num(aligned_uT.mag)[None], aligned.mag_available)},
        ground_truth=aligned.truth_q,
        position_truth=log.position_truth,
        declination=log_declination(log.parameters, log.parameter_changes),
    )
