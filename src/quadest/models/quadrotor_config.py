"""The quadrotor's config nodes as the objects the simulation and its filter model take:
physical parameters, controller gains, scenario, sensor triads and the filter's Q and R."""

from __future__ import annotations

import numpy as np

from quadest.quadrotor.controller import BacksteppingGains
from quadest.quadrotor.params import QuadrotorParams
from quadest.quadrotor.scenarios import SCENARIOS
from quadest.sensors.mimu import TriadSpec


def quadrotor_params(model_cfg) -> QuadrotorParams:
    """Physical parameters of ``cfg.model``."""
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


def controller_gains(controller_cfg) -> BacksteppingGains:
    """Backstepping gains of ``cfg.model.controller``."""
    c = controller_cfg
    return BacksteppingGains(
        position=tuple(c.position), altitude=tuple(c.altitude), attitude=tuple(c.attitude), yaw=tuple(c.yaw),
        max_tilt=c.max_tilt,
    )  # fmt: skip


def scenario(scenario_cfg):
    """The scenario object of ``cfg.scenario``."""
    scenario_cls = SCENARIOS[scenario_cfg.name]
    return scenario_cls(**{k: scenario_cfg[k] for k in scenario_cls.__dataclass_fields__})


def triad_spec(triad_cfg, error_scale: float) -> TriadSpec:
    """Error specification of ``cfg.sensor.accel`` or ``cfg.sensor.gyro``, scaled by ``error_scale``."""
    return TriadSpec(**{k: float(triad_cfg[k]) for k in TriadSpec.__dataclass_fields__}).scaled(error_scale)


def group_diagonal(state_names: tuple[str, ...], by_group) -> np.ndarray:
    """Per-state values from per-group settings (``velocity``, ``angle``, ``angle_rate``)."""

    def group(name: str) -> str:
        if name.startswith("v"):
            return "velocity"
        return "angle_rate" if name.endswith("_dot") else "angle"

    return np.array([float(by_group[group(s)]) for s in state_names])


def measurement_covariance(
    accel: TriadSpec, gyro: TriadSpec, sample_period: float, duration: float, inflation: float
) -> np.ndarray:
    """R: white-noise variance ``σ_c²/T`` plus the random-walk drift variance at mid-run
    ``σ_bc² · duration/2`` (drift the filter does not estimate is treated as noise), per axis."""

    def var(t: TriadSpec) -> float:
        return t.white_noise_std(sample_period) ** 2 + t.bias_random_walk**2 * duration / 2.0

    return inflation * np.diag([var(accel)] * 3 + [var(gyro)] * 3)
