"""Range checks that a schema cannot express, run before any work starts.

Each failed check raises :class:`~quadest.errors.ConfigError` with one line naming the key, the
value and what is allowed. Types and unknown keys are already checked by the schemas at
composition.
"""

from __future__ import annotations

import math

from quadest.errors import ConfigError
from quadest.estimators.registry import builtin_estimators, report_plugin_problems, resolve
from quadest.models.quadrotor import FORMULATIONS
from quadest.models.registry import model_specs
from quadest.quadrotor.scenarios import SCENARIOS


def _positive(key: str, value, what: str = "must be > 0") -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(key, value, what)


def _non_negative(key: str, value) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
        raise ConfigError(key, value, "must be >= 0 (a standard deviation or error level)")


def state_dimension(cfg) -> int:
    """State dimension of the configured filter model."""
    return model_specs()[cfg.model.name].state_dimension(cfg)


def validate_run(cfg) -> None:
    _positive("runs", cfg.runs, "must be an integer >= 1")
    if cfg.seed < 0:
        raise ConfigError("seed", cfg.seed, "must be an integer >= 0")
    _positive("sample_period", cfg.sample_period, "must be > 0 seconds")
    if not cfg.duration >= cfg.sample_period:
        raise ConfigError(
            "duration", cfg.duration, f"must be at least one sample period (sample_period={cfg.sample_period})"
        )
    _positive("divergence_bound", cfg.divergence_bound)
    if cfg.workers < 0:
        raise ConfigError("workers", cfg.workers, "must be >= 0 (0: one process per estimator, up to the CPU count)")
    if cfg.output.saved_runs < 0:
        raise ConfigError("output.saved_runs", cfg.output.saved_runs, "must be >= 0")


def validate_model(cfg) -> None:
    specs = model_specs()
    if cfg.model.name not in specs:
        raise ConfigError("model.name", cfg.model.name, f"one of {sorted(specs)}")
    spec = specs[cfg.model.name]
    spec.validate(cfg)
    if spec.uses_quadrotor_groups:
        validate_sensor(cfg)
        validate_scenario(cfg)


def validate_quadrotor(cfg) -> None:
    """Range checks of ``model=quadrotor``."""
    m = cfg.model
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
        _positive(f"model.{key}", m[key])
    _non_negative("model.rotor_speed_min", m.rotor_speed_min)
    if not m.rotor_speed_min < m.rotor_speed_max:
        raise ConfigError(
            "model.rotor_speed_min", m.rotor_speed_min, f"must be below model.rotor_speed_max={m.rotor_speed_max}"
        )
    _positive("model.truth_substeps", m.truth_substeps, "must be an integer >= 1")
    for key in ("inertia", "translational_drag", "rotational_drag"):
        values = list(m[key])
        if len(values) != 3:
            raise ConfigError(f"model.{key}", values, "must list 3 values (x, y, z)")
        for i, v in enumerate(values):
            (_positive if key == "inertia" else _non_negative)(f"model.{key}[{i}]", v)
    for group in ("velocity", "angle", "angle_rate"):
        _positive(
            f"model.process_noise.{group}", m.process_noise[group], "must be > 0 (a standard deviation per sample)"
        )
        _positive(f"model.initial_std.{group}", m.initial_std[group], "must be > 0 (a standard deviation)")
    n = state_dimension(cfg)
    rho = m.initial_std.correlation
    if not -1.0 / (n - 1) < rho < 1.0:
        raise ConfigError(
            "model.initial_std.correlation",
            rho,
            f"must lie in ({-1.0 / (n - 1):.3g}, 1) for a positive-definite P0 with n={n}",
        )
    for key in ("position", "altitude", "attitude", "yaw"):
        gains = list(m.controller[key])
        if len(gains) != 2 or min(gains) <= 0:
            raise ConfigError(f"model.controller.{key}", gains, "must be two gains [alpha1, alpha2], both > 0")
    _positive("model.controller.max_tilt", m.controller.max_tilt, "must be in (0, pi/2) rad")
    if m.controller.max_tilt >= math.pi / 2:
        raise ConfigError("model.controller.max_tilt", m.controller.max_tilt, "must be in (0, pi/2) rad")


def validate_sensor(cfg) -> None:
    s = cfg.sensor
    _positive("sensor.error_scale", s.error_scale, "must be > 0 (it also scales the white noise the filters rely on)")
    for triad in ("accel", "gyro"):
        for key, value in s[triad].items():
            _non_negative(f"sensor.{triad}.{key}", value)
        _positive(
            f"sensor.{triad}.white_noise",
            s[triad].white_noise,
            "must be > 0 (the filters' measurement covariance is built from it)",
        )
    if s.encoder.lines < 0:
        raise ConfigError("sensor.encoder.lines", s.encoder.lines, "must be >= 0 (0 disables quantisation)")
    _non_negative("sensor.encoder.noise_std", s.encoder.noise_std)


def validate_scenario(cfg) -> None:
    sc = cfg.scenario
    if sc.name not in SCENARIOS:
        raise ConfigError("scenario.name", sc.name, f"one of {sorted(SCENARIOS)}")
    _non_negative("scenario.initial_position_std", sc.initial_position_std)
    _positive("scenario.altitude", sc.altitude)
    _non_negative("scenario.takeoff_time", sc.takeoff_time)
    for key in ("period", "spin_up_time", "transition_time"):
        if key in sc:
            _positive(f"scenario.{key}", sc[key])


def validate_estimators(cfg) -> None:
    if not cfg.estimator:
        raise ConfigError("estimator", "[]", f"select at least one of {sorted(builtin_estimators())}")
    report_plugin_problems({node.get("kind", label) for label, node in cfg.estimator.items()})
    n = state_dimension(cfg)
    for label, node in cfg.estimator.items():
        resolve(label, node)
        if "alpha" in node:
            alpha, kappa = node.alpha, node.get("kappa", 0.0)
            if not alpha > 0:
                raise ConfigError(f"estimator.{label}.alpha", alpha, "must be > 0 (typically 1e-4 <= alpha <= 1)")
            if not alpha**2 * (n + kappa) > 0:
                raise ConfigError(
                    f"estimator.{label}.kappa",
                    kappa,
                    f"n + lambda = alpha^2 (n + kappa) must be > 0, so kappa > {-n} for n={n}",
                )


def validate(cfg) -> None:
    """Check every range constraint of a composed config; raise :class:`ConfigError` on the first."""
    validate_run(cfg)
    validate_model(cfg)
    validate_estimators(cfg)
