"""Monte Carlo data of ``model=quadrotor``: fly the scenario, measure it with the MIMU and the
encoders, and bind the filter model to the runs' assumed sensor errors.

The same pieces serve the closed loop (:mod:`quadest.closed_loop`): :func:`draw_plant` draws every
random number a :class:`~quadest.quadrotor.plant.QuadrotorPlant` needs from the same streams, and
:func:`record_quadrotor_data` measures a truth however it was flown."""

from __future__ import annotations

import numpy as np

from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.config_checks import validate_quadrotor
from quadest.models.quadrotor import QuadrotorFilterModel, quadrotor_layout
from quadest.models.quadrotor_config import (
    controller_gains,
    group_diagonal,
    measurement_covariance,
    quadrotor_params,
    scenario,
    triad_spec,
)
from quadest.models.schemas import QuadrotorModelConf
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.data import sample_count
from quadest.montecarlo.initial import draw_initial_estimates, initial_covariance
from quadest.montecarlo.streams import run_seed_sequences, run_streams
from quadest.numerics import quaternion as quat
from quadest.quadrotor.controller import BacksteppingController
from quadest.quadrotor.plant import PlantDraws
from quadest.quadrotor.scenarios import Scenario
from quadest.quadrotor.simulate import TruthTrajectory, simulate_truth
from quadest.sensors.base import SensorModel, TrueMotion
from quadest.sensors.encoders import encoder_resolution, measure_rotor_speeds
from quadest.sensors.mimu import TriadErrors, draw_triad_errors, measure_triad
from quadest.sensors.noise_laws import noise_law_from_config
from quadest.simulation.aiding import measure_aiding, sensor_context, validate_aiding
from quadest.simulation.spec import ModelSpec


def draw_start(flown: Scenario, streams: dict) -> np.ndarray:
    """(B, 3) start positions: on the ground, horizontally scattered by the ``"start"`` stream."""
    start = np.zeros((len(streams["start"]), 3))
    for i, rng in enumerate(streams["start"]):
        start[i, :2] = flown.initial_position_std * rng.standard_normal(2)
    return start


def fly_scenario(settings: DataSettings, streams: dict):
    """``(params, scenario, truth)``: the quadrotor of ``settings.model`` flown by the backstepping
    controller through ``settings.scenario`` once per run, each run starting at a horizontal position
    drawn from its ``"start"`` stream."""
    mcfg, T = settings.model, float(settings.sample_period)
    params = quadrotor_params(mcfg)
    flown = scenario(settings.scenario)
    start = draw_start(flown, streams)
    controller = BacksteppingController(params, controller_gains(mcfg.controller))
    truth = simulate_truth(params, controller, flown, start, float(settings.duration), T, int(mcfg.truth_substeps))
    return params, flown, truth


def _triads(settings: DataSettings, streams: dict):
    """The accelerometer's and gyro's specs, drawn deterministic errors and noise laws."""
    scfg, scale = settings.sensor, float(settings.sensor.error_scale)
    accel, gyro = triad_spec(scfg.accel, scale), triad_spec(scfg.gyro, scale)
    errors = draw_triad_errors(accel, streams["accel_errors"]), draw_triad_errors(gyro, streams["gyro_errors"])
    laws = noise_law_from_config(scfg.accel.noise_law), noise_law_from_config(scfg.gyro.noise_law)
    return (accel, gyro), errors, laws


def draw_plant(settings: DataSettings, streams: dict, flown: Scenario) -> PlantDraws:
    """Every random number of the runs' plant, from the same streams and in the same order as
    :func:`build_quadrotor_data` draws them: a triad's drift and noise are what
    :func:`measure_triad` adds to a zero input through error-free axes, the encoders' noise what
    :func:`measure_rotor_speeds` adds to zero speeds without quantisation."""
    runs, T = len(streams["start"]), float(settings.sample_period)
    K1 = sample_count(float(settings.duration), T) + 1
    (accel, gyro), (accel_errors, gyro_errors), (accel_law, gyro_law) = _triads(settings, streams)
    zeros3, nominal = np.zeros((runs, K1, 3)), TriadErrors.nominal(runs)
    return PlantDraws(
        start=draw_start(flown, streams),
        accel_errors=accel_errors,
        gyro_errors=gyro_errors,
        accel_noise=measure_triad(accel, nominal, zeros3, T, streams["accel_noise"], accel_law),
        gyro_noise=measure_triad(gyro, nominal, zeros3, T, streams["gyro_noise"], gyro_law),
        encoder_noise=measure_rotor_speeds(
            np.zeros((runs, K1, 4)), 0, float(settings.sensor.encoder.noise_std), T, streams["encoder"]
        ),
        state_noise=np.stack([rng.standard_normal((K1, 12)) for rng in streams["state_sensor"]]),
    )


def quadrotor_filter_model(
    settings: DataSettings,
    accel_errors: TriadErrors,
    gyro_errors: TriadErrors,
    aiding: dict[str, SensorModel] | None = None,
) -> QuadrotorFilterModel:
    """The filter model of ``settings.model``, bound to the runs' assumed sensor errors (the drawn
    ones when ``calibrated``, error-free otherwise) and to its further sensors ``aiding``."""
    mcfg, T, runs = settings.model, float(settings.sample_period), accel_errors.bias.shape[0]
    scale = float(settings.sensor.error_scale)
    accel, gyro = triad_spec(settings.sensor.accel, scale), triad_spec(settings.sensor.gyro, scale)
    assumed_acc, assumed_gyro = (
        (accel_errors, gyro_errors) if mcfg.calibrated else (TriadErrors.nominal(runs), TriadErrors.nominal(runs))
    )
    state_names = QuadrotorFilterModel.formulation_state_names(mcfg.formulation)
    Q = np.diag(group_diagonal(state_names, mcfg.process_noise) ** 2)
    R = measurement_covariance(accel, gyro, T, float(settings.duration), float(mcfg.measurement_noise_inflation))
    return QuadrotorFilterModel(
        quadrotor_params(mcfg), mcfg.formulation, T, Q, R, assumed_acc, assumed_gyro, aiding=aiding
    )


def initial_condition(settings: DataSettings, state_names: tuple[str, ...], x_true0: np.ndarray, streams: dict):
    """``(x0, P0)``: P0 from ``settings.model.initial_std`` and each run's x0 ~ N(x_true0, P0) drawn
    from its ``"initial"`` stream, ``x_true0`` (B, n) the true filter state at sample 0."""
    std = settings.model.initial_std
    P0 = initial_covariance(group_diagonal(state_names, std), float(std.correlation))
    return draw_initial_estimates(x_true0, P0, streams["initial"]), P0


def data_labels(settings: DataSettings, flown: Scenario) -> dict:
    """The descriptive columns of a quadrotor job's metrics table (``aiding`` only with further
    sensors)."""
    mcfg, scfg, T = settings.model, settings.sensor, float(settings.sample_period)
    labels = {
        "model": mcfg.name, "formulation": mcfg.formulation, "calibrated": bool(mcfg.calibrated),
        "sensor": scfg.name, "error_scale": float(scfg.error_scale), "scenario": flown.name,
        "encoder_resolution": encoder_resolution(int(scfg.encoder.lines), T) if scfg.encoder.lines else 0.0,
    }  # fmt: skip
    if getattr(mcfg, "aiding", None):  # model=quadrotor's further sensors (the closed loop flies without)
        labels["aiding"] = "+".join(mcfg.aiding)
    return labels


def _measure(
    settings: DataSettings, streams: dict, truth: TruthTrajectory
) -> tuple[np.ndarray, np.ndarray, TriadErrors, TriadErrors]:
    """``(measurements (B, K+1, 6), inputs (B, K+1, 4), accel errors, gyro errors)``: the MIMU and
    the encoders of ``truth`` for the runs of ``streams``, with the triads' drawn errors."""
    scfg, T = settings.sensor, float(settings.sample_period)
    (accel, gyro), (accel_errors, gyro_errors), (accel_law, gyro_law) = _triads(settings, streams)
    z_acc = measure_triad(accel, accel_errors, truth.specific_force, T, streams["accel_noise"], accel_law)
    z_gyro = measure_triad(gyro, gyro_errors, truth.state[..., 9:12], T, streams["gyro_noise"], gyro_law)
    u = measure_rotor_speeds(
        truth.state[..., 12:16], int(scfg.encoder.lines), float(scfg.encoder.noise_std), T, streams["encoder"]
    )
    return np.concatenate([z_acc, z_gyro], axis=-1), u, accel_errors, gyro_errors


def record_quadrotor_data(
    settings: DataSettings, streams: dict, flown: Scenario, truth: TruthTrajectory
) -> MonteCarloData:
    """What the filters see of ``truth``, however it was flown: MIMU and encoders measured from the
    runs' streams, the filter model bound to the assumed sensor errors, and the initial estimates."""
    z, u, accel_errors, gyro_errors = _measure(settings, streams, truth)
    model = quadrotor_filter_model(settings, accel_errors, gyro_errors)
    x_true = model.truth_to_state(truth.state)
    companion_truth = model.truth_to_companion(truth.state)
    return _data(settings, streams, flown, model, truth.time, x_true, companion_truth, u, z)


def _data(
    settings: DataSettings, streams: dict, flown: Scenario, model, time, x_true, companion_truth, u, z, sensors=None
) -> MonteCarloData:
    """The :class:`MonteCarloData` of the recorded arrays, with the initial estimates drawn from
    the runs' ``"initial"`` streams."""
    x0, P0 = initial_condition(settings, model.state_names, x_true[:, 0], streams)
    return MonteCarloData(
        model=model,
        time=time,
        truth=x_true,
        companion_truth=companion_truth,
        inputs=u,
        measurements=z,
        x0=x0,
        P0=P0,
        companion0=companion_truth[:, 0].copy(),
        estimator_seeds=run_seed_sequences(int(settings.seed), len(streams["start"]), settings.first_run)["estimator"],
        labels=data_labels(settings, flown),
        sensors=sensors or {},
    )


DATA_CHUNK_RUNS = 100


def build_quadrotor_data(settings: DataSettings) -> MonteCarloData:
    """Fly the scenario for ``settings.runs`` runs and record what the filters see.

    The runs are flown and measured ``DATA_CHUNK_RUNS`` at a time, each chunk from its runs' own
    streams, and only what the filters see is kept (the filter state, the companion values, the
    inputs and the measurements of each sample), so the 16-state truth, the specific force and
    the sensors' noise arrays exist for one chunk at a time. Every run is the run flown alone
    (each run's generators, element-wise arithmetic), so the data do not depend on the chunking.

    Further sensors (``model.aiding``, docs/sensors.md) measure the whole batch at once after the
    chunks (position, velocity and attitude are kept for it), so a sensor whose availability
    depends on every run sees them all.
    """
    runs = int(settings.runs)
    streams = run_streams(int(settings.seed), runs, settings.first_run)
    arrays: list[np.ndarray] = []
    errors: list[tuple[TriadErrors, TriadErrors]] = []
    motion: list[np.ndarray] = []
    time = flown = None
    for first in range(0, runs, DATA_CHUNK_RUNS):
        chunk = slice(first, min(first + DATA_CHUNK_RUNS, runs))
        sub = {name: generators[chunk] for name, generators in streams.items()}
        _params, flown, truth = fly_scenario(settings, sub)
        z, u, accel_errors, gyro_errors = _measure(settings, sub, truth)
        model = quadrotor_filter_model(settings, accel_errors, gyro_errors)
        parts = (model.truth_to_state(truth.state), model.truth_to_companion(truth.state), u, z)
        if not arrays:
            arrays = [np.empty((runs, *part.shape[1:])) for part in parts]
        for out, part in zip(arrays, parts, strict=True):
            out[chunk] = part
        errors.append((accel_errors, gyro_errors))
        if settings.model.aiding:
            motion.append(truth.state[..., 0:9].copy())
        time = truth.time
        del truth, parts, z, u
    records, aiding = {}, {}
    if motion:
        state = np.concatenate(motion)
        truth_motion = TrueMotion(time, state[..., 0:3], state[..., 3:6], quat.from_euler(state[..., 6:9]))
        records, aiding = measure_aiding(
            settings,
            truth_motion,
            streams,
            quadrotor_layout(settings.model.formulation),
            sensor_context(settings, settings.model.calibrated, settings.model.measurement_noise_inflation),
        )
    model = quadrotor_filter_model(settings, *(_concatenate([e[i] for e in errors]) for i in (0, 1)), aiding=aiding)
    return _data(settings, streams, flown, model, time, *arrays, sensors=records)


def _concatenate(errors: list[TriadErrors]) -> TriadErrors:
    """The triad errors of consecutive chunks of runs as one batch."""
    return TriadErrors(
        *(np.concatenate([getattr(e, name) for e in errors]) for name in ("matrix", "asymmetry", "bias"))
    )


def validate_quadrotor_model(settings: DataSettings) -> None:
    """Range checks of ``model=quadrotor``: the quadrotor's and its further sensors'
    (:func:`~quadest.simulation.aiding.validate_aiding`; the closed loop flies without them)."""
    validate_quadrotor(settings)
    if settings.model.aiding:
        if settings.loop != "open":
            raise ConfigError("model.aiding", list(settings.model.aiding), "further sensors need loop=open")
        validate_aiding(settings, quadrotor_layout(settings.model.formulation))


MODEL = ModelSpec(
    "quadrotor",
    QuadrotorModelConf,
    build_quadrotor_data,
    lambda settings: len(QuadrotorFilterModel.formulation_state_names(settings.model.formulation)),
    validate_quadrotor_model,
    uses_quadrotor_groups=True,
)
