"""Monte Carlo data: one truth, input and measurement record per run, shared by every estimator.

Randomness comes only from ``np.random.SeedSequence(seed)``: it spawns one child per run, and
each run's child spawns one stream per purpose (start point, accelerometer errors, gyro errors,
accelerometer noise, gyro noise, encoder noise, initial estimate). So every estimator sees the
same draws (common random numbers), run ``i`` is the same whatever the number of runs, and a
sweep over ``sensor.error_scale`` scales the same standard-normal draws.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.models.base import FilterModel
from quadest.models.quadrotor import QuadrotorFilterModel
from quadest.quadrotor.controller import BacksteppingController, BacksteppingGains
from quadest.quadrotor.params import QuadrotorParams
from quadest.quadrotor.scenarios import SCENARIOS
from quadest.quadrotor.simulate import simulate_truth
from quadest.sensors.encoders import encoder_resolution, measure_rotor_speeds
from quadest.sensors.mimu import TriadErrors, TriadSpec, draw_triad_errors, measure_triad

STREAMS = (
    "start",
    "accel_errors",
    "gyro_errors",
    "accel_noise",
    "gyro_noise",
    "encoder",
    "initial",
    "process",
    "measurement",
)  # append only: existing streams keep their draws


@dataclass
class MonteCarloData:
    """Everything the runner needs for a batch of B runs over K+1 samples.

    Attributes:
        model: the filter model, bound to the batch.
        time: (K+1,) sample times.
        truth: (B, K+1, n) true filter state.
        companion_truth: (B, K+1, nc) true companion values (see :class:`FilterModel`).
        inputs: (B, K+1, nu_measured) measured inputs (before companions are appended).
        measurements: (B, K+1, m).
        x0: (B, n) initial estimates, drawn from N(truth[:, 0], P0).
        P0: (n, n) initial covariance.
        companion0: (B, nc) initial companion values the filters start from.
        labels: descriptive columns for the metrics table.
    """

    model: FilterModel
    time: np.ndarray
    truth: np.ndarray
    companion_truth: np.ndarray
    inputs: np.ndarray
    measurements: np.ndarray
    x0: np.ndarray
    P0: np.ndarray
    companion0: np.ndarray
    labels: dict = field(default_factory=dict)


def sample_count(duration: float, sample_period: float) -> int:
    """Number of filter steps K in a run: samples at t_k = k T, k = 0..K."""
    return round(duration / sample_period)


def run_streams(seed: int, runs: int) -> dict[str, list[np.random.Generator]]:
    """One generator per (purpose, run), all from ``SeedSequence(seed)``."""
    per_run = [child.spawn(len(STREAMS)) for child in np.random.SeedSequence(seed).spawn(runs)]
    return {name: [np.random.default_rng(ss[j]) for ss in per_run] for j, name in enumerate(STREAMS)}


def quadrotor_params(model_cfg) -> QuadrotorParams:
    return QuadrotorParams(
        mass=model_cfg.mass,
        arm=model_cfg.arm,
        inertia=tuple(model_cfg.inertia),
        rotor_inertia=model_cfg.rotor_inertia,
        thrust_factor=model_cfg.thrust_factor,
        drag_factor=model_cfg.drag_factor,
        gravity=model_cfg.gravity,
        translational_drag=tuple(model_cfg.translational_drag),
        rotational_drag=tuple(model_cfg.rotational_drag),
        motor_time_constant=model_cfg.motor_time_constant,
        rotor_speed_min=model_cfg.rotor_speed_min,
        rotor_speed_max=model_cfg.rotor_speed_max,
    )


def triad_spec(triad_cfg, error_scale: float) -> TriadSpec:
    return TriadSpec(**{k: float(triad_cfg[k]) for k in TriadSpec.__dataclass_fields__}).scaled(error_scale)


def group_diagonal(state_names: tuple[str, ...], by_group) -> np.ndarray:
    """Per-state values from per-group settings (``velocity``, ``angle``, ``angle_rate``)."""

    def group(name: str) -> str:
        if name.startswith("v"):
            return "velocity"
        return "angle_rate" if name.endswith("_dot") else "angle"

    return np.array([float(by_group[group(s)]) for s in state_names])


def initial_covariance(std: np.ndarray, correlation: float) -> np.ndarray:
    """``P0 = D C D`` with ``D = diag(std)`` and equicorrelation ``C = (1 − ρ) I + ρ 11ᵀ``."""
    n = std.size
    C = (1.0 - correlation) * np.eye(n) + correlation * np.ones((n, n))
    return std[:, None] * C * std[None, :]


def measurement_covariance(
    accel: TriadSpec, gyro: TriadSpec, sample_period: float, duration: float, inflation: float
) -> np.ndarray:
    """R: white-noise variance ``σ_c²/T`` plus the random-walk drift variance at mid-run
    ``σ_bc² · duration/2`` (drift the filter does not estimate is treated as noise), per axis."""

    def var(t: TriadSpec) -> float:
        return t.white_noise_std(sample_period) ** 2 + t.bias_random_walk**2 * duration / 2.0

    return inflation * np.diag([var(accel)] * 3 + [var(gyro)] * 3)


def build_quadrotor_data(cfg) -> MonteCarloData:
    """Fly the scenario for ``cfg.runs`` runs and record what the filters see."""
    mcfg, scfg = cfg.model, cfg.sensor
    runs, T = int(cfg.runs), float(cfg.sample_period)
    streams = run_streams(int(cfg.seed), runs)
    params = quadrotor_params(mcfg)
    gains = BacksteppingGains(
        position=tuple(mcfg.controller.position), altitude=tuple(mcfg.controller.altitude),
        attitude=tuple(mcfg.controller.attitude), yaw=tuple(mcfg.controller.yaw),
        max_tilt=mcfg.controller.max_tilt,
    )  # fmt: skip
    scenario_cls = SCENARIOS[cfg.scenario.name]
    scenario = scenario_cls(**{k: cfg.scenario[k] for k in scenario_cls.__dataclass_fields__})
    start = np.zeros((runs, 3))
    for i, rng in enumerate(streams["start"]):
        start[i, :2] = scenario.initial_position_std * rng.standard_normal(2)
    truth = simulate_truth(
        params, BacksteppingController(params, gains), scenario, start, float(cfg.duration), T, int(mcfg.truth_substeps)
    )

    scale = float(scfg.error_scale)
    accel, gyro = triad_spec(scfg.accel, scale), triad_spec(scfg.gyro, scale)
    accel_errors = draw_triad_errors(accel, streams["accel_errors"])
    gyro_errors = draw_triad_errors(gyro, streams["gyro_errors"])
    z_acc = measure_triad(accel, accel_errors, truth.specific_force, T, streams["accel_noise"])
    z_gyro = measure_triad(gyro, gyro_errors, truth.state[..., 9:12], T, streams["gyro_noise"])
    u = measure_rotor_speeds(
        truth.state[..., 12:16], int(scfg.encoder.lines), float(scfg.encoder.noise_std), T, streams["encoder"]
    )

    assumed_acc, assumed_gyro = (
        (accel_errors, gyro_errors) if mcfg.calibrated else (TriadErrors.nominal(runs), TriadErrors.nominal(runs))
    )
    probe = QuadrotorFilterModel(params, mcfg.formulation, T, np.eye(1), np.eye(6), assumed_acc, assumed_gyro)
    Q = np.diag(group_diagonal(probe.state_names, mcfg.process_noise) ** 2)
    R = measurement_covariance(accel, gyro, T, float(cfg.duration), float(mcfg.measurement_noise_inflation))
    model = QuadrotorFilterModel(params, mcfg.formulation, T, Q, R, assumed_acc, assumed_gyro)

    x_true = model.truth_to_state(truth.state)
    P0 = initial_covariance(group_diagonal(model.state_names, mcfg.initial_std), float(mcfg.initial_std.correlation))
    L0 = np.linalg.cholesky(P0)
    x0 = np.array([x_true[i, 0] + L0 @ rng.standard_normal(model.n) for i, rng in enumerate(streams["initial"])])
    companion_truth = model.truth_to_companion(truth.state)
    labels = {
        "model": mcfg.name, "formulation": mcfg.formulation, "calibrated": bool(mcfg.calibrated),
        "sensor": scfg.name, "error_scale": scale, "scenario": scenario.name,
        "encoder_resolution": encoder_resolution(int(scfg.encoder.lines), T) if scfg.encoder.lines else 0.0,
    }  # fmt: skip
    return MonteCarloData(
        model,
        truth.time,
        x_true,
        companion_truth,
        u,
        np.concatenate([z_acc, z_gyro], axis=-1),
        x0,
        P0,
        companion_truth[:, 0].copy(),
        labels,
    )
