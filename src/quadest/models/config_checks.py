"""Range checks of each model option's ``model`` settings (:class:`~quadest.config.settings.DataSettings`),
run before any work starts (the schemas already check types and keys). :mod:`quadest.simulation.registry`
pairs each with its model."""

from __future__ import annotations

import math

from quadest.config.ranges import require_non_negative, require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.quadrotor import FORMULATIONS, QuadrotorFilterModel


def validate_quadrotor(settings: DataSettings) -> None:
    """Range checks of ``model=quadrotor``."""
    m = settings.model
    if m.formulation not in FORMULATIONS:
        raise ConfigError("model.formulation", m.formulation, f"one of {list(FORMULATIONS)}")
    for key in (
        "mass",
        "arm",
        "rotor_inertia",
        "thrust_factor",
        "drag_factor",
        "gravity",
        "motor_time_constant",
        "rotor_speed_max",
        "measurement_noise_inflation",
    ):
        require_positive(f"model.{key}", getattr(m, key))
    require_non_negative("model.rotor_speed_min", m.rotor_speed_min)
    if not m.rotor_speed_min < m.rotor_speed_max:
        raise ConfigError(
            "model.rotor_speed_min", m.rotor_speed_min, f"must be below model.rotor_speed_max={m.rotor_speed_max}"
        )
    require_positive("model.truth_substeps", m.truth_substeps, "must be an integer >= 1")
    for key in ("inertia", "translational_drag", "rotational_drag"):
        values = list(getattr(m, key))
        if len(values) != 3:
            raise ConfigError(f"model.{key}", values, "must list 3 values (x, y, z)")
        for i, v in enumerate(values):
            (require_positive if key == "inertia" else require_non_negative)(f"model.{key}[{i}]", v)
    for group in ("velocity", "angle", "angle_rate"):
        require_positive(
            f"model.process_noise.{group}",
            getattr(m.process_noise, group),
            "must be > 0 (a standard deviation per sample)",
        )
        require_positive(
            f"model.initial_std.{group}", getattr(m.initial_std, group), "must be > 0 (a standard deviation)"
        )
    n = len(QuadrotorFilterModel.formulation_state_names(m.formulation))
    rho = m.initial_std.correlation
    if not -1.0 / (n - 1) < rho < 1.0:
        raise ConfigError(
            "model.initial_std.correlation",
            rho,
            f"must lie in ({-1.0 / (n - 1):.3g}, 1) for a positive-definite P0 with n={n}",
        )
    for key in ("position", "altitude", "attitude", "yaw"):
        gains = list(getattr(m.controller, key))
        if len(gains) != 2 or min(gains) <= 0:
            raise ConfigError(f"model.controller.{key}", gains, "must be two gains [alpha1, alpha2], both > 0")
    require_positive("model.controller.max_tilt", m.controller.max_tilt, "must be in (0, pi/2) rad")
    if m.controller.max_tilt >= math.pi / 2:
        raise ConfigError("model.controller.max_tilt", m.controller.max_tilt, "must be in (0, pi/2) rad")


def validate_linear(settings: DataSettings) -> None:
    """Range checks of ``model=linear``."""
    m = settings.model
    require_positive("model.acceleration_psd", m.acceleration_psd)
    require_positive("model.position_noise_std", m.position_noise_std)
    if not -1 < m.measurement_correlation < 1:
        raise ConfigError("model.measurement_correlation", m.measurement_correlation, "must lie in (-1, 1)")
    for key in ("initial_state", "initial_std"):
        if len(getattr(m, key)) != 4:
            raise ConfigError(f"model.{key}", list(getattr(m, key)), "must list 4 values (px, py, vx, vy)")
    for i, v in enumerate(m.initial_std):
        require_positive(f"model.initial_std[{i}]", v)
    if not -1 / 3 < m.initial_correlation < 1:
        raise ConfigError("model.initial_correlation", m.initial_correlation, "must lie in (-1/3, 1) for n=4")


def validate_ungm(settings: DataSettings) -> None:
    """Range checks of ``model=ungm``."""
    m = settings.model
    require_positive("model.Q", m.Q, "must be > 0 (process noise variance)")
    require_positive("model.R", m.R, "must be > 0 (measurement noise variance)")
    require_positive("model.P0", m.P0, "must be > 0 (initial variance of the filters)")
    require_non_negative("model.x0_var", m.x0_var, "must be >= 0 (0: a deterministic initial state)")
