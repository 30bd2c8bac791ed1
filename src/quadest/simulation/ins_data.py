"""Monte Carlo data of ``model=ins``: fly the shared quadrotor, measure it with the MIMU and the
aiding sensors, and bind :class:`~quadest.models.ins.InsFilterModel` to the runs (docs/ins.md).

- Truth: :func:`~quadest.simulation.quadrotor_data.fly_scenario`; the attitude as a quaternion of
  the truth's ZYX Euler angles; the true biases are each run's turn-on bias plus its random-walk
  drift (:func:`quadest.simulation.attitude_data._measure_with_truth_bias`).
- IMU (the input): the MIMU of ``cfg.sensor`` with its own streams (so adding an aiding sensor
  changes no MIMU draw) measuring, at each sample, the mean of the true rate and specific force
  over the step that follows (trapezoid of the truth's samples: a Δθ/Δv IMU).
- Aiding sensors: ``model.aiding`` in update order, each from its own stream: ``gps``,
  ``barometer``, ``vision`` (``cfg.sensor.gps`` …) and ``magnetometer`` (``model.magnetometer``,
  as ``model=attitude``).
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
"""

from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from quadest.config.ranges import require_non_negative, require_positive
from quadest.errors import ConfigError
from quadest.models.config_checks import validate_quadrotor
from quadest.models.ins import CHARTS, InsFilterModel
from quadest.models.ins_sensors import AidingSensor, BarometerAiding, GpsAiding, MagnetometerAiding, VisionAiding
from quadest.models.quadrotor_config import triad_spec
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.initial import draw_initial_estimates
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.quadrotor.scenarios import PlatformApproach
from quadest.sensors.barometer import measure_barometer
from quadest.sensors.gps import measure_gps
from quadest.sensors.magnetometer import measure_magnetometer, sample_stride
from quadest.sensors.mimu import TriadErrors, draw_triad_errors
from quadest.sensors.noise_laws import check_noise_law, noise_law_from_config
from quadest.sensors.record import SensorRecord
from quadest.sensors.vision import KINDS, MOUNTS, measure_vision, mount_rotation
from quadest.simulation.attitude_data import _measure_with_truth_bias
from quadest.simulation.quadrotor_data import fly_scenario

AIDING = ("gps", "barometer", "vision", "magnetometer")


def interval_means(y: np.ndarray) -> np.ndarray:
    """(B, K+1, d): sample k holds the mean of ``y`` over [t_k, t_{k+1}] by the trapezoid rule
    (the last sample, which has no step after it, keeps its value)."""
    out = np.array(y, dtype=float, copy=True)
    out[:, :-1] = 0.5 * (y[:, :-1] + y[:, 1:])
    return out


def _check_rate(key: str, rate, sample_period: float) -> None:
    require_positive(key, rate, "must be > 0 Hz")
    try:
        sample_stride(float(rate), sample_period)
    except ConfigError as err:
        raise ConfigError(key, rate, err.allowed) from None


def validate_ins(cfg) -> None:
    """Range checks of ``model=ins``: the quadrotor's (it flies the truth), the aiding sensors in
    use and the filters' noise."""
    validate_quadrotor(cfg)
    m, s, T = cfg.model, cfg.sensor, float(cfg.sample_period)
    if m.attitude_chart not in CHARTS:
        raise ConfigError("model.attitude_chart", m.attitude_chart, f"one of {list(CHARTS)}")
    aiding = list(m.aiding)
    for name in aiding:
        if name not in AIDING or aiding.count(name) > 1:
            raise ConfigError("model.aiding", aiding, f"distinct names from {list(AIDING)}")
    for key in ("attitude", "position", "velocity"):
        require_non_negative(f"model.ins_process_noise.{key}", m.ins_process_noise[key])
    require_positive("model.ins_process_noise.inflation", m.ins_process_noise.inflation)
    for key in ("attitude", "position", "velocity", "gyro_bias", "accel_bias"):
        require_positive(f"model.ins_initial_std.{key}", m.ins_initial_std[key], "must be > 0 (P0 from it)")
    if "gps" in aiding:
        _check_rate("sensor.gps.rate", s.gps.rate, T)
        for key in ("latency", "position_drift"):
            require_non_negative(f"sensor.gps.{key}", s.gps[key])
        for key in ("horizontal_noise", "vertical_noise", "velocity_noise", "drift_time"):
            require_positive(f"sensor.gps.{key}", s.gps[key], "must be > 0 (R is built from it)")
        check_noise_law("sensor.gps.noise_law", s.gps.noise_law)
    if "barometer" in aiding:
        _check_rate("sensor.barometer.rate", s.barometer.rate, T)
        for key in ("bias", "bias_random_walk", "scale_factor"):
            require_non_negative(f"sensor.barometer.{key}", s.barometer[key])
        require_positive("sensor.barometer.white_noise", s.barometer.white_noise, "must be > 0 (R is built from it)")
        check_noise_law("sensor.barometer.noise_law", s.barometer.noise_law)
    if "vision" in aiding:
        _validate_vision(s.vision, T)
    if "magnetometer" in aiding:
        _check_rate("model.magnetometer.rate", m.magnetometer.rate, T)
        require_positive("model.magnetometer.white_noise", m.magnetometer.white_noise, "must be > 0 (R from it)")


def _validate_vision(v, sample_period: float) -> None:
    _check_rate("sensor.vision.rate", v.rate, sample_period)
    if v.kind not in KINDS:
        raise ConfigError("sensor.vision.kind", v.kind, f"one of {list(KINDS)}")
    if v.mount not in MOUNTS:
        raise ConfigError("sensor.vision.mount", v.mount, f"one of {list(MOUNTS)}")
    for key in ("pixel_noise", "bearing_noise", "los_noise", "focal_length", "max_range"):
        require_positive(f"sensor.vision.{key}", v[key])
    for key in ("misalignment", "focal_scale"):
        require_non_negative(f"sensor.vision.{key}", v[key])
    if len(v.image_size) != 2 or min(v.image_size) <= 0:
        raise ConfigError("sensor.vision.image_size", list(v.image_size), "two sizes [width, height] > 0 in px")
    beacons = [list(b) for b in v.beacons]
    if len(beacons) < 3 or any(len(b) != 3 for b in beacons):
        raise ConfigError("sensor.vision.beacons", beacons, "at least 3 beacons, each [x, y, z] in m (earth frame)")
    check_noise_law("sensor.vision.noise_law", v.noise_law)


def _aiding_sensor(
    name: str, cfg, x_true: np.ndarray, streams: dict, platform: np.ndarray | None
) -> tuple[SensorRecord, AidingSensor]:
    """The record and the filters' model of one aiding sensor; ``platform`` (K+1, 3): the moving
    beacon platform's position, or ``None`` for beacons fixed in the earth frame."""
    T, duration = float(cfg.sample_period), float(cfg.duration)
    inflation = float(cfg.model.measurement_noise_inflation)
    q, p, v = x_true[..., 0:4], x_true[..., 4:7], x_true[..., 7:10]
    if name == "gps":
        spec = OmegaConf.to_object(cfg.sensor.gps)
        R = np.diag(spec.white_std() ** 2)
        R[0:3, 0:3] += spec.position_drift**2 * np.eye(3)
        delay = spec.latency_steps(T) * T
        return measure_gps(spec, p, v, T, streams["gps"]), GpsAiding(spec, delay, inflation * R)
    if name == "barometer":
        spec = OmegaConf.to_object(cfg.sensor.barometer)
        record = measure_barometer(spec, p[..., 2], T, streams["barometer"])
        return record, BarometerAiding(inflation * spec.variance(duration) * np.eye(1))
    if name == "vision":
        spec = OmegaConf.to_object(cfg.sensor.vision)
        R = inflation * spec.noise_std**2 * np.eye(spec.m)
        aiding = VisionAiding(spec, mount_rotation(spec.mount, spec.tilt_deg), R, moving_platform=platform is not None)
        relative = p if platform is None else p - platform
        return measure_vision(spec, q, relative, T, streams["vision"]), aiding
    mcfg = cfg.model
    mag = triad_spec(mcfg.magnetometer, float(cfg.sensor.error_scale))
    errors = draw_triad_errors(mag, streams["mag_errors"])
    m_e = np.array(mcfg.magnetometer.earth_field, dtype=float)
    rate = float(mcfg.magnetometer.rate)
    record = measure_magnetometer(mag, errors, q, m_e, T, rate, streams["mag_noise"])
    r = mag.white_noise_std(sample_stride(rate, T) * T) ** 2 + mag.bias_random_walk**2 * duration / 2.0
    assumed = errors if mcfg.calibrated else TriadErrors.nominal(x_true.shape[0])
    return record, MagnetometerAiding(m_e, assumed, inflation * r * np.eye(3))


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


def build_ins_data(cfg) -> MonteCarloData:
    """Fly the scenario for ``cfg.runs`` runs and record what the INS filters see."""
    mcfg, scfg = cfg.model, cfg.sensor
    runs, T, seed = int(cfg.runs), float(cfg.sample_period), int(cfg.seed)
    streams = run_streams(seed, runs)
    _, flown, truth = fly_scenario(cfg, streams)

    scale = float(scfg.error_scale)
    accel, gyro = triad_spec(scfg.accel, scale), triad_spec(scfg.gyro, scale)
    accel_errors = draw_triad_errors(accel, streams["accel_errors"])
    gyro_errors = draw_triad_errors(gyro, streams["gyro_errors"])
    accel_law = noise_law_from_config(scfg.accel.get("noise_law"))
    gyro_law = noise_law_from_config(scfg.gyro.get("noise_law"))
    z_acc, accel_bias = _measure_with_truth_bias(
        accel, accel_errors, interval_means(truth.specific_force), T, streams["accel_noise"], accel_law
    )
    z_gyro, gyro_bias = _measure_with_truth_bias(
        gyro, gyro_errors, interval_means(truth.state[..., 9:12]), T, streams["gyro_noise"], gyro_law
    )
    state = truth.state
    x_true = InsFilterModel.truth_state(state[..., 6:9], state[..., 0:3], state[..., 3:6], gyro_bias, accel_bias)

    platform = flown.platform_position(truth.time) if isinstance(flown, PlatformApproach) else None
    records, aiding = {}, {}
    for name in mcfg.aiding:
        records[name], aiding[name] = _aiding_sensor(name, cfg, x_true, streams, platform)
    assumed = (gyro_errors, accel_errors) if mcfg.calibrated else (TriadErrors.nominal(runs),) * 2
    Q = process_noise(gyro, accel, mcfg.ins_process_noise, T)
    model = InsFilterModel(
        T, float(mcfg.gravity), Q, aiding, *assumed, chart=mcfg.attitude_chart, batch_size=runs,
        platform_input=platform is not None,
    )  # fmt: skip
    inputs = [z_gyro, z_acc] + ([] if platform is None else [np.broadcast_to(platform, z_gyro.shape)])

    s0 = mcfg.ins_initial_std
    groups = ("attitude", "position", "velocity", "gyro_bias", "accel_bias")
    P0 = np.diag(np.repeat([float(s0[k]) ** 2 for k in groups], 3))
    offsets = draw_initial_estimates(np.zeros((len(streams["initial"]), 15)), P0, streams["initial"])
    x0 = model.boxplus(x_true[:, 0], offsets)
    labels = {
        "model": mcfg.name, "calibrated": bool(mcfg.calibrated), "sensor": scfg.name, "error_scale": scale,
        "scenario": flown.name, "attitude_chart": mcfg.attitude_chart, "aiding": "+".join(mcfg.aiding),
    }  # fmt: skip
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
        estimator_seeds=run_seed_sequences(seed, runs)["estimator"],
        labels=labels,
        sensors=records,
    )
