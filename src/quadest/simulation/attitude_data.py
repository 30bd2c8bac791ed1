"""Monte Carlo data of ``model=attitude``: fly the shared quadrotor, measure it with the MIMU and
the magnetometer, and bind :class:`~quadest.models.attitude.AttitudeFilterModel` to the runs.

- Truth: :func:`~quadest.simulation.quadrotor_data.fly_scenario` (earth frame z up, ZYX Euler
  angles in the 16-state truth, columns 6:9); the MIMU samples the true rate and specific force
  and gives the true biases, each run's turn-on bias plus its random-walk drift
  (:func:`~quadest.simulation.imu.measure_mimu`).
- Input: the gyro sample and, with ``known_acceleration``, the true earth-frame acceleration
  ``a_e = R f_b + g_e`` (an ideal aiding source); otherwise ``a_e = 0`` and ``R_acc`` grows by
  ``acceleration_std²`` per axis, as a replay without aiding must do.
- Noise covariances from the sensor spec: ``R_acc = σ_a²/T``, ``R_mag = σ_m²/T_mag`` plus the
  hard-iron drift the filter does not estimate at mid-run; ``Q`` per step:
  ``δθ: σ_g² T + attitude²``, ``δb_g: σ_bg² T``, ``δb_a: σ_ba² T``, all times ``inflation``.
  ``attitude`` (default 0) is room for propagation error beyond the gyro noise: with the gyro
  averaged over each step (:func:`~quadest.simulation.imu.interval_means`) the one-step
  residual of the truth on the figure eight is 6.2e-6 rad per axis, the gyro noise ``σ_g √(T/2)``
  itself; a zero-order hold would leave ``½ ω̇ T²`` ≈ 1e-4 rad, correlated from step to step.
- x0 = truth ⊞ L0 w with ``w ~ N(0, I)`` from each run's ``"initial"`` stream (the quaternion
  moves on the manifold, not by adding to its components).

With ``model.recording`` (a file or an EuRoC-layout folder with the IMU and the 16-column INS
truth, :func:`~quadest.simulation.recorded.read_imu_recordings`, docs/euroc.md) nothing is flown:
the recorded gyro (averaged over each step as above) is the input, the recorded accelerometer the
measurement, the reference's attitude and biases the truth, and the magnetometer measures the
reference's attitude (its own streams: a synthetic magnetometer on a recorded flight). With
``known_acceleration`` the earth-frame acceleration is the reference velocity's derivative (central
differences, one-sided at the ends); the triads are taken as nominal.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from quadest.config.ranges import require_non_negative, require_positive
from quadest.config.settings import DataSettings
from quadest.models.attitude import AttitudeFilterModel
from quadest.models.config_checks import validate_quadrotor
from quadest.models.quadrotor_config import triad_spec
from quadest.models.schemas import AttitudeModelConf
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.initial import draw_initial_estimates
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.quadrotor.kinematics import rotation
from quadest.sensors.base import TrueMotion
from quadest.sensors.magnetometer import Magnetometer
from quadest.sensors.mimu import TriadErrors, TriadSpec
from quadest.simulation.aiding import sensor_context
from quadest.simulation.imu import interval_means, measure_mimu, read_recorded_imu, recorded_imu_data
from quadest.simulation.quadrotor_data import fly_scenario
from quadest.simulation.recorded import resolve_recording
from quadest.simulation.spec import ModelSpec


def validate_attitude(settings: DataSettings) -> None:
    """Range checks of ``model=attitude``: the quadrotor's (it flies the truth), the magnetometer's
    and the filters' noise."""
    validate_quadrotor(settings)
    m = settings.model
    require_positive("model.acceleration_std", m.acceleration_std)
    Magnetometer.validate(m.magnetometer, Magnetometer.key(), float(settings.sample_period))
    require_non_negative("model.attitude_process_noise.attitude", m.attitude_process_noise.attitude)
    require_positive("model.attitude_process_noise.inflation", m.attitude_process_noise.inflation)
    for key in ("attitude", "gyro_bias", "accel_bias"):
        std = getattr(m.attitude_initial_std, key)
        require_positive(f"model.attitude_initial_std.{key}", std, "must be > 0 (P0 from it)")
    if m.recording is not None:
        resolve_recording(m.recording)


def _filter_noise(settings: DataSettings, gyro: TriadSpec, accel: TriadSpec) -> tuple[np.ndarray, float]:
    """``(Q, R_acc per axis)`` of the filters (module docstring)."""
    m, T = settings.model, float(settings.sample_period)
    q_att = gyro.white_noise**2 * T + float(m.attitude_process_noise.attitude) ** 2
    Q = np.diag([q_att] * 3 + [gyro.bias_random_walk**2 * T] * 3 + [accel.bias_random_walk**2 * T] * 3)
    r_acc = accel.white_noise_std(T) ** 2 + (0.0 if m.known_acceleration else float(m.acceleration_std) ** 2)
    return float(m.attitude_process_noise.inflation) * Q, r_acc


def _initial_covariance(settings: DataSettings) -> np.ndarray:
    s0 = settings.model.attitude_initial_std
    return np.diag([float(s0.attitude) ** 2] * 3 + [float(s0.gyro_bias) ** 2] * 3 + [float(s0.accel_bias) ** 2] * 3)


def build_attitude_data(settings: DataSettings) -> MonteCarloData:
    """Fly the scenario for ``settings.runs`` runs and record what the attitude filters see (or,
    with ``model.recording``, :func:`build_recorded_attitude_data`)."""
    if settings.model.recording is not None:
        return build_recorded_attitude_data(settings)
    mcfg, scfg = settings.model, settings.sensor
    runs, T, seed = int(settings.runs), float(settings.sample_period), int(settings.seed)
    streams = run_streams(seed, runs, settings.first_run)
    _, flown, truth = fly_scenario(settings, streams)
    g_e = np.array([0.0, 0.0, -float(mcfg.gravity)])

    scale = float(scfg.error_scale)
    imu = measure_mimu(settings, truth.specific_force, truth.state[..., 9:12], streams)
    angles = truth.state[..., 6:9]
    x_true = AttitudeFilterModel.truth_state(angles, imu.gyro_bias, imu.accel_bias)
    noise = float(mcfg.measurement_noise_inflation)
    magnetometer = Magnetometer(mcfg.magnetometer, sensor_context(settings, mcfg.calibrated, noise))
    motion = TrueMotion(truth.time, truth.state[..., 0:3], truth.state[..., 3:6], x_true[..., :4])
    z_mag = magnetometer.simulate(motion, {name: streams[name] for name in Magnetometer.stream_names()})

    known = bool(mcfg.known_acceleration)
    a_e = np.einsum("bkij,bkj->bki", rotation(angles), truth.specific_force) + g_e if known else np.zeros_like(angles)

    Q, r_acc = _filter_noise(settings, imu.gyro, imu.accel)
    assumed = (imu.gyro_errors, imu.accel_errors) if mcfg.calibrated else (TriadErrors.nominal(runs),) * 2
    model = AttitudeFilterModel(
        T,
        g_e,
        magnetometer.mag_earth,
        Q,
        noise * r_acc * np.eye(3),
        magnetometer.noise_covariance(),
        *assumed,
        magnetometer.assumed_errors(),
        batch_size=runs,
    )

    P0 = _initial_covariance(settings)
    offsets = draw_initial_estimates(np.zeros((len(streams["initial"]), 9)), P0, streams["initial"])
    x0 = model.boxplus(x_true[:, 0], offsets)
    labels = {
        "model": mcfg.name,
        "calibrated": bool(mcfg.calibrated),
        "known_acceleration": known,
        "sensor": scfg.name,
        "error_scale": scale,
        "scenario": flown.name,
        "mag_rate": float(mcfg.magnetometer.rate),
    }
    return MonteCarloData(
        model=model,
        time=truth.time,
        truth=x_true,
        companion_truth=np.zeros((runs, truth.time.size, 0)),
        inputs=np.concatenate([interval_means(imu.z_gyro), a_e], axis=-1),
        measurements=imu.z_acc,
        x0=x0,
        P0=P0,
        companion0=np.zeros((runs, 0)),
        estimator_seeds=run_seed_sequences(seed, runs, settings.first_run)["estimator"],
        labels=labels,
        sensors={"mag": z_mag},
    )


def build_recorded_attitude_data(settings: DataSettings) -> MonteCarloData:
    """The recordings of ``model.recording`` as the attitude filters' data (module docstring): the
    recorded gyro the input, the accelerometer the measurement, a synthetic magnetometer beside.
    A recording that is not an IMU recording or does not fit the job raises
    :class:`~quadest.errors.ConfigError` (:func:`~quadest.simulation.imu.read_recorded_imu`,
    :func:`~quadest.simulation.recorded.recorded_data`)."""
    mcfg, scfg = settings.model, settings.sensor
    runs, T = int(settings.runs), float(settings.sample_period)
    recordings, streams, sensed = read_recorded_imu(settings)
    time = recordings[0].time
    reference = np.stack([r.truth for r in recordings])
    noise = float(mcfg.measurement_noise_inflation)
    magnetometer = Magnetometer(mcfg.magnetometer, sensor_context(sensed, mcfg.calibrated, noise))
    motion = TrueMotion(time - time[0], reference[..., 4:7], reference[..., 7:10], reference[..., 0:4])
    z_mag = magnetometer.simulate(motion, {name: streams[name] for name in Magnetometer.stream_names()})
    known = bool(mcfg.known_acceleration)
    a_e = np.gradient(reference[..., 7:10], time, axis=1) if known else np.zeros_like(reference[..., 7:10])
    recordings = [
        dataclasses.replace(
            r,
            measurements=r.inputs[:, 3:6],
            truth=np.concatenate([r.truth[:, 0:4], r.truth[:, 10:16]], axis=-1),  # [q, b_g, b_a]
            inputs=np.concatenate([interval_means(r.inputs[None, :, 0:3])[0], a], axis=-1),
        )
        for r, a in zip(recordings, a_e, strict=True)
    ]
    scale = float(scfg.error_scale)
    Q, r_acc = _filter_noise(settings, triad_spec(scfg.gyro, scale), triad_spec(scfg.accel, scale))
    model = AttitudeFilterModel(
        T,
        np.array([0.0, 0.0, -float(mcfg.gravity)]),
        magnetometer.mag_earth,
        Q,
        noise * r_acc * np.eye(3),
        magnetometer.noise_covariance(),
        None,
        None,
        magnetometer.assumed_errors(),
        batch_size=runs,
    )
    labels = {
        "model": mcfg.name,
        "recording": str(mcfg.recording),
        "known_acceleration": known,
        "sensor": scfg.name,
        "mag_rate": float(mcfg.magnetometer.rate),
        **recordings[0].notes,
    }
    return recorded_imu_data(
        settings, model, recordings, _initial_covariance(settings), streams, {"mag": z_mag}, labels
    )


MODEL = ModelSpec(  # n_err = 9: attitude error, gyro and accelerometer biases
    "attitude",
    AttitudeModelConf,
    build_attitude_data,
    lambda _: 9,
    validate_attitude,
    uses_quadrotor_groups=True,
)
