"""The quadrotor's typed settings (schema instances, :class:`~quadest.config.settings.DataSettings`)
as the objects the simulation and its filter model take: physical parameters, controller gains,
scenario, sensor triads and the filter's Q and R."""

from __future__ import annotations

from typing import Any

import numpy as np

from quadest.quadrotor.controller import BacksteppingGains
from quadest.quadrotor.params import QuadrotorParams
from quadest.quadrotor.scenario_registry import scenario_classes
from quadest.quadrotor.scenarios import Scenario
from quadest.sensors.mimu import TriadSpec


def quadrotor_params(model: Any) -> QuadrotorParams:
    """Physical parameters of the ``model`` settings (a :class:`~quadest.models.schemas.QuadrotorFlightConf`)."""
    return QuadrotorParams(
        mass=model.mass,
        arm=model.arm,
        inertia=tuple(model.inertia),
        rotor_inertia=model.rotor_inertia,
        thrust_factor=model.thrust_factor,
        drag_factor=model.drag_factor,
        gravity=model.gravity,
        translational_drag=tuple(model.translational_drag),
        rotational_drag=tuple(model.rotational_drag),
        motor_time_constant=model.motor_time_constant,
        rotor_speed_min=model.rotor_speed_min,
        rotor_speed_max=model.rotor_speed_max,
    )


def controller_gains(controller: Any) -> BacksteppingGains:
    """Backstepping gains of ``model.controller`` (a :class:`~quadest.models.schemas.ControllerConf`)."""
    c = controller
    return BacksteppingGains(
        position=tuple(c.position), altitude=tuple(c.altitude), attitude=tuple(c.attitude), yaw=tuple(c.yaw),
        max_tilt=c.max_tilt,
    )  # fmt: skip


def scenario(settings: Any) -> Scenario:
    """A fresh scenario object of the ``scenario`` settings (an instance of its schema class)."""
    scenario_cls = scenario_classes()[settings.name]
    return scenario_cls(**{k: getattr(settings, k) for k in scenario_cls.__dataclass_fields__})


def triad_spec(triad: TriadSpec, error_scale: float) -> TriadSpec:
    """Error specification of ``sensor.accel`` or ``sensor.gyro`` (a triad's settings), scaled by
    ``error_scale``."""
    return TriadSpec(**{k: float(getattr(triad, k)) for k in TriadSpec.__dataclass_fields__}).scaled(error_scale)


def group_diagonal(state_names: tuple[str, ...], by_group: Any) -> np.ndarray:
    """Per-state values from per-group settings (``velocity``, ``angle``, ``angle_rate``)."""

    def group(name: str) -> str:
        if name.startswith("v"):
            return "velocity"
        return "angle_rate" if name.endswith("_dot") else "angle"

    return np.array([float(getattr(by_group, group(s))) for s in state_names])


def measurement_covariance(
    accel: TriadSpec, gyro: TriadSpec, sample_period: float, duration: float, inflation: float
) -> np.ndarray:
    """R: white-noise variance ``σ_c²/T`` plus the random-walk drift variance at mid-run
    ``σ_bc² · duration/2`` (drift the filter does not estimate is treated as noise), per axis."""

    def var(t: TriadSpec) -> float:
        return t.white_noise_std(sample_period) ** 2 + t.bias_random_walk**2 * duration / 2.0

    return inflation * np.diag([var(accel)] * 3 + [var(gyro)] * 3)
