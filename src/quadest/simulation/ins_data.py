"""Monte Carlo data of ``model=ins``: fly the shared quadrotor, measure it with the MIMU and the
aiding sensors, and bind :class:`~quadest.models.ins.InsFilterModel` to the runs (docs/ins.md).

- Truth: :func:`~quadest.simulation.quadrotor_data.fly_scenario`; the attitude as a quaternion of
  the truth's ZYX Euler angles; the true biases are each run's turn-on bias plus its random-walk
  drift (:func:`~quadest.simulation.imu.measure_mimu`).
- IMU (the input): the MIMU of ``settings.sensor`` with its own streams (so adding an aiding sensor
  changes no MIMU draw) measuring, at each sample, the mean of the true rate and specific force
  over the step that follows (trapezoid of the truth's samples: a Δθ/Δv IMU).
- Aiding sensors: ``model.aiding`` in update order, any registered sensor
  (:mod:`quadest.sensors.registry`; built in: ``gps``, ``barometer``, ``vision`` with settings
  ``settings.sensor.gps`` …, and ``magnetometer`` with ``model.magnetometer``, as ``model=attitude``),
  each from its own streams, through :mod:`quadest.simulation.aiding`: the INS offers them its
  attitude, position and velocity (:func:`~quadest.models.ins.ins_layout`).
- Moving platform (scenario ``platform_approach``, docs/seed004-landing.md): the camera's beacons
  are in the platform's frame, the truth is measured at ``p − p_P(t)``, and the platform position
  ``p_P`` is appended to the input (``u = [ω̃, f̃, p_P]``) for the filters' camera model.
- ``Q`` per step: the IMU's white noise carried through the mechanisation (attitude
  ``σ_g² T``; velocity ``σ_a² T`` and position ``σ_a² T³/4``, correlated by ``σ_a² T²/2``), bias
  random walks ``σ_b² T``, plus ``ins_process_noise``'s one-sigma terms per step for what the
  mechanisation neglects, all times ``inflation``. Each sensor's ``R`` is its white-noise
  variance plus the variance of the errors the filter does not estimate (GPS drift, barometer
  bias and mid-run drift, magnetometer hard-iron drift), times ``measurement_noise_inflation``.
- x0 = truth ⊞ L0 w with ``w ~ N(0, I)`` from each run's ``"initial"`` stream.

With ``model.recording`` (a file or an EuRoC-layout folder, :mod:`quadest.simulation.recorded`,
:mod:`quadest.simulation.euroc`) nothing is flown: each recording is one run whose inputs are the
IMU samples ``[ω̃, f̃]`` as measured (instantaneous; turned into the means over the following step
by :func:`~quadest.simulation.imu.interval_means`, as the simulated IMU) and whose truth is
the 16-column INS state of the reference. Its first ``duration`` seconds are used (all of it when
shorter), its first sample is the filters' start (:func:`~quadest.simulation.recorded.recorded_data`
with ``starts_at_first_sample``), the triads are taken as nominal (a real IMU's scale errors are
unknown), ``Q`` and ``P0`` come from the same keys as above, and the aiding sensors of
``model.aiding`` measure the reference (each from its own streams: synthetic fixes of a recorded
flight).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from quadest.config.ranges import require_non_negative, require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.config_checks import validate_quadrotor
from quadest.models.ins import ATT, CHARTS, POS, VEL, InsFilterModel, ins_layout
from quadest.models.quadrotor_config import triad_spec
from quadest.models.schemas import InsModelConf
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.initial import draw_initial_estimates
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.quadrotor.scenarios import PlatformApproach
from quadest.sensors.base import TrueMotion
from quadest.sensors.mimu import TriadErrors
from quadest.simulation.aiding import measure_aiding, sensor_context, validate_aiding
from quadest.simulation.imu import interval_means, measure_mimu, read_recorded_imu, recorded_imu_data
from quadest.simulation.quadrotor_data import fly_scenario
from quadest.simulation.recorded import resolve_recording
from quadest.simulation.spec import ModelSpec


def validate_ins(settings: DataSettings) -> None:
    """Range checks of ``model=ins``: the quadrotor's (it flies the truth), the filters' noise and
    the aiding sensors in use (:func:`~quadest.simulation.aiding.validate_aiding`)."""
    validate_quadrotor(settings)
    m = settings.model
    if m.attitude_chart not in CHARTS:
        raise ConfigError("model.attitude_chart", m.attitude_chart, f"one of {list(CHARTS)}")
    for key in ("attitude", "position", "velocity"):
        require_non_negative(f"model.ins_process_noise.{key}", getattr(m.ins_process_noise, key))
    require_positive("model.ins_process_noise.inflation", m.ins_process_noise.inflation)
    for key in ("attitude", "position", "velocity", "gyro_bias", "accel_bias"):
        require_positive(f"model.ins_initial_std.{key}", getattr(m.ins_initial_std, key), "must be > 0 (P0 from it)")
    validate_aiding(settings, ins_layout(platform_input=True))
    if m.recording is not None:
        resolve_recording(m.recording)


def process_noise(gyro, accel, extra, sample_period: float) -> np.ndarray:
    """``Q`` (15, 15) per step (module docstring) from the gyro and accelerometer specs and the
    ``ins_process_noise`` node ``extra``."""
    T = sample_period
    sa2, sg2 = accel.white_noise**2, gyro.white_noise**2
    Q = np.zeros((15, 15))
    eye = np.eye(3)
    Q[0:3, 0:3] = (sg2 * T + float(extra.attitude) ** 2) * eye
    Q[3:6, 3:6] = (sa2 * T**3 / 4.0 + float(extra.position) ** 2) * eye
    Q[6:9, 6:9] = (sa2 * T + float(extra.velocity) ** 2) * eye
    Q[3:6, 6:9] = Q[6:9, 3:6] = sa2 * T**2 / 2.0 * eye
    Q[9:12, 9:12] = gyro.bias_random_walk**2 * T * eye
    Q[12:15, 12:15] = accel.bias_random_walk**2 * T * eye
    return float(extra.inflation) * Q


def build_ins_data(settings: DataSettings) -> MonteCarloData:
    """Fly the scenario for ``settings.runs`` runs and record what the INS filters see (or, with
    ``model.recording``, :func:`build_recorded_ins_data`)."""
    if settings.model.recording is not None:
        return build_recorded_ins_data(settings)
    mcfg, scfg = settings.model, settings.sensor
    runs, T, seed = int(settings.runs), float(settings.sample_period), int(settings.seed)
    streams = run_streams(seed, runs, settings.first_run)
    _, flown, truth = fly_scenario(settings, streams)

    scale = float(scfg.error_scale)
    state = truth.state
    imu = measure_mimu(settings, interval_means(truth.specific_force), interval_means(state[..., 9:12]), streams)
    x_true = InsFilterModel.truth_state(
        state[..., 6:9], state[..., 0:3], state[..., 3:6], imu.gyro_bias, imu.accel_bias
    )

    platform = flown.platform_position(truth.time) if isinstance(flown, PlatformApproach) else None
    motion = TrueMotion(truth.time, x_true[..., 4:7], x_true[..., 7:10], x_true[..., 0:4], platform)
    records, aiding = measure_aiding(
        settings,
        motion,
        streams,
        ins_layout(platform_input=platform is not None),
        sensor_context(settings, settings.model.calibrated, settings.model.measurement_noise_inflation),
    )
    assumed = (imu.gyro_errors, imu.accel_errors) if mcfg.calibrated else (TriadErrors.nominal(runs),) * 2
    Q = process_noise(imu.gyro, imu.accel, mcfg.ins_process_noise, T)
    model = InsFilterModel(
        T,
        float(mcfg.gravity),
        Q,
        aiding,
        *assumed,
        chart=mcfg.attitude_chart,
        batch_size=runs,
        platform_input=platform is not None,
    )
    inputs = [imu.z_gyro, imu.z_acc] + ([] if platform is None else [np.broadcast_to(platform, imu.z_gyro.shape)])

    P0 = _initial_covariance(settings)
    offsets = draw_initial_estimates(np.zeros((len(streams["initial"]), 15)), P0, streams["initial"])
    x0 = model.boxplus(x_true[:, 0], offsets)
    labels = {
        "model": mcfg.name,
        "calibrated": bool(mcfg.calibrated),
        "sensor": scfg.name,
        "error_scale": scale,
        "scenario": flown.name,
        "attitude_chart": mcfg.attitude_chart,
        "aiding": "+".join(mcfg.aiding),
    }
    K1 = truth.time.size
    return MonteCarloData(
        model=model,
        time=truth.time,
        truth=x_true,
        companion_truth=np.zeros((runs, K1, 0)),
        inputs=np.concatenate(inputs, axis=-1),
        measurements=np.zeros((runs, K1, 0)),
        x0=x0,
        P0=P0,
        companion0=np.zeros((runs, 0)),
        estimator_seeds=run_seed_sequences(seed, runs, settings.first_run)["estimator"],
        labels=labels,
        sensors=records,
    )


def _initial_covariance(settings: DataSettings) -> np.ndarray:
    s0 = settings.model.ins_initial_std
    groups = ("attitude", "position", "velocity", "gyro_bias", "accel_bias")
    return np.diag(np.repeat([float(getattr(s0, k)) ** 2 for k in groups], 3))


def build_recorded_ins_data(settings: DataSettings) -> MonteCarloData:
    """The recordings of ``model.recording`` as the INS filters' data (module docstring): the
    IMU samples the input, the aiding sensors of ``model.aiding`` measuring the reference.
    A recording that is not an IMU recording or does not fit the job raises
    :class:`~quadest.errors.ConfigError` (:func:`~quadest.simulation.imu.read_recorded_imu`,
    :func:`~quadest.simulation.recorded.recorded_data`)."""
    mcfg, scfg = settings.model, settings.sensor
    runs, T = int(settings.runs), float(settings.sample_period)
    read, streams, sensed = read_recorded_imu(settings)
    recordings = [dataclasses.replace(r, inputs=interval_means(r.inputs[None])[0]) for r in read]
    truth = np.stack([r.truth for r in recordings])
    motion = TrueMotion(recordings[0].time - recordings[0].time[0], truth[..., POS], truth[..., VEL], truth[..., ATT])
    records, aiding = measure_aiding(
        sensed, motion, streams, ins_layout(), sensor_context(sensed, mcfg.calibrated, mcfg.measurement_noise_inflation)
    )
    scale = float(scfg.error_scale)
    gyro, accel = triad_spec(scfg.gyro, scale), triad_spec(scfg.accel, scale)
    Q = process_noise(gyro, accel, mcfg.ins_process_noise, T)
    model = InsFilterModel(T, float(mcfg.gravity), Q, aiding, chart=mcfg.attitude_chart, batch_size=runs)
    labels = {
        "model": mcfg.name,
        "recording": str(mcfg.recording),
        "sensor": scfg.name,
        "attitude_chart": mcfg.attitude_chart,
        "aiding": "+".join(mcfg.aiding),
        **recordings[0].notes,
    }
    return recorded_imu_data(settings, model, recordings, _initial_covariance(settings), streams, records, labels)


MODEL = ModelSpec(  # n_err = 15
    "ins", InsModelConf, build_ins_data, lambda _: 15, validate_ins, uses_quadrotor_groups=True
)
