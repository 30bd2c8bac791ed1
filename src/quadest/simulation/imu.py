"""What the data of ``model=attitude`` and ``model=ins`` share: the MIMU measuring the flown truth
with its true biases, the mean of a sampled signal over each step, and the start of a job on
recorded IMU data.

- :func:`measure_mimu`: the accelerometer and gyro triads of ``settings.sensor`` (their specs
  scaled by ``sensor.error_scale``, their turn-on errors from the ``"accel_errors"`` and
  ``"gyro_errors"`` streams, their noise from ``"accel_noise"`` and ``"gyro_noise"`` with each
  triad's noise law) measuring the given specific force and rate, with the true biases: each
  run's turn-on bias plus its random-walk drift, recovered by measuring the same draws once more
  without white noise (:func:`measure_with_truth_bias`).
- :func:`interval_means`: ``(y_k + y_{k+1})/2`` at step k, the mean of ``y`` over [t_k, t_{k+1}]
  by the trapezoid rule (a Δθ/Δv IMU's output; for the attitude filters' gyro input the midpoint
  rule of ``q_{k+1} = q_k ⊗ exp(ω̄_k T)``).
- :func:`read_recorded_imu`: the recordings of ``model.recording``, each run's streams and the
  settings with the recording's duration (what the aiding sensors measure over);
  :func:`recorded_imu_data`: the job's data from them, the IMU's first sample the filters' start.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass

import numpy as np

from quadest.config.settings import DataSettings
from quadest.models.base import FilterModel
from quadest.models.quadrotor_config import triad_spec
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.initial import draw_initial_estimates
from quadest.montecarlo.streams import run_streams
from quadest.sensors.mimu import TriadErrors, TriadSpec, draw_triad_errors, measure_triad
from quadest.sensors.noise_laws import NoiseLaw, noise_law_from_config
from quadest.sensors.record import SensorRecord
from quadest.simulation.recorded import IMU_STEP_RTOL, read_imu_recordings, recorded_data
from quadest.simulation.recording import Recording

Streams = dict[str, list[np.random.Generator]]
"""Each purpose's generator per run (:func:`~quadest.montecarlo.streams.run_streams`)."""


def interval_means(y: np.ndarray) -> np.ndarray:
    """(B, K+1, d): sample k holds the mean of ``y`` over [t_k, t_{k+1}] by the trapezoid rule
    (the last sample, which has no step after it, keeps its value). For a gyro this is the rate
    over the step as an IMU's delta-angle output gives it (PX4's integrated gyro): a zero-order
    hold instead would leave an error ``½ ω̇ T²`` per step, correlated from step to step and not
    white process noise."""
    out = np.array(y, dtype=float, copy=True)
    out[:, :-1] = 0.5 * (y[:, :-1] + y[:, 1:])
    return out


def measure_with_truth_bias(
    spec: TriadSpec, errors: TriadErrors, y: np.ndarray, T: float, rngs: list[np.random.Generator], law: NoiseLaw
) -> tuple[np.ndarray, np.ndarray]:
    """``(z, b)``: the triad's samples of ``y`` (B, K+1, 3) and its true bias ``b0 + b(t)``
    (B, K+1, 3). The bias comes from the same draws measured without white noise (copies of the
    generators), so it is exactly the drift inside ``z``."""
    z = measure_triad(spec, errors, y, T, [copy.deepcopy(r) for r in rngs], law)
    quiet = TriadSpec(**{**spec.__dict__, "white_noise": 0.0})
    drift_only = measure_triad(quiet, errors, y, T, rngs, law)
    bias = drift_only - (errors.apply(y) - errors.bias[:, None])
    return z, bias


@dataclass(frozen=True)
class MimuSamples:
    """The MIMU's specs, its drawn turn-on errors, its samples and its true biases (B, K+1, 3)."""

    accel: TriadSpec
    gyro: TriadSpec
    accel_errors: TriadErrors
    gyro_errors: TriadErrors
    z_acc: np.ndarray
    z_gyro: np.ndarray
    accel_bias: np.ndarray
    gyro_bias: np.ndarray


def measure_mimu(settings: DataSettings, specific_force: np.ndarray, rate: np.ndarray, streams: Streams) -> MimuSamples:
    """The MIMU of ``settings.sensor`` measuring ``specific_force`` and ``rate`` (B, K+1, 3) with
    each run's streams (module docstring)."""
    scfg, T = settings.sensor, float(settings.sample_period)
    scale = float(scfg.error_scale)
    accel, gyro = triad_spec(scfg.accel, scale), triad_spec(scfg.gyro, scale)
    accel_errors = draw_triad_errors(accel, streams["accel_errors"])
    gyro_errors = draw_triad_errors(gyro, streams["gyro_errors"])
    accel_law = noise_law_from_config(scfg.accel.noise_law)
    gyro_law = noise_law_from_config(scfg.gyro.noise_law)
    z_acc, accel_bias = measure_with_truth_bias(
        accel, accel_errors, specific_force, T, streams["accel_noise"], accel_law
    )
    z_gyro, gyro_bias = measure_with_truth_bias(gyro, gyro_errors, rate, T, streams["gyro_noise"], gyro_law)
    return MimuSamples(accel, gyro, accel_errors, gyro_errors, z_acc, z_gyro, accel_bias, gyro_bias)


def read_recorded_imu(settings: DataSettings) -> tuple[list[Recording], Streams, DataSettings]:
    """``(recordings, streams, sensed)``: the IMU recordings of ``model.recording``
    (:func:`~quadest.simulation.recorded.read_imu_recordings`), each run's streams, and
    ``settings`` with the recording's duration, over which the aiding sensors measure.

    Raises:
        ConfigError: ``model.recording`` is not an IMU recording.
    """
    recordings = read_imu_recordings(settings)
    streams = run_streams(int(settings.seed), int(settings.runs), settings.first_run)
    time = recordings[0].time
    return recordings, streams, dataclasses.replace(settings, duration=float(time[-1] - time[0]))


def recorded_imu_data(
    settings: DataSettings,
    model: FilterModel,
    recordings: list[Recording],
    P0: np.ndarray,
    streams: Streams,
    sensors: dict[str, SensorRecord],
    labels: dict[str, object],
) -> MonteCarloData:
    """The data of IMU ``recordings`` (their truth in ``model``'s state), one run each, by
    :func:`~quadest.simulation.recorded.recorded_data`: the recording's first sample is the
    filters' start (its first input drives the first step), its step ``sample_period`` to a
    logger's jitter (``IMU_STEP_RTOL``); the filters start at ``truth ⊞ L0 w``, ``P0 = L0 L0ᵀ``,
    ``w ~ N(0, I)`` from each run's ``"initial"`` stream."""
    offsets = draw_initial_estimates(np.zeros((int(settings.runs), P0.shape[0])), P0, streams["initial"])
    x0 = model.boxplus(np.stack([r.truth[0] for r in recordings]), offsets)
    return recorded_data(
        settings,
        model,
        recordings,
        x0,
        P0,
        starts_at_first_sample=True,
        step_rtol=IMU_STEP_RTOL,
        sensors=sensors,
        labels=labels,
    )
