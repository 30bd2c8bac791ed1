"""The ``model`` config group: each option's schema, data builder, state dimension and checks."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from quadest.config.schema import LinearModelConf, QuadrotorModelConf, UNGMModelConf
from quadest.errors import ConfigError
from quadest.montecarlo import MonteCarloData, build_quadrotor_data


@dataclass(frozen=True)
class ModelSpec:
    """A model option: ``build(cfg)`` makes the Monte Carlo data, ``state_dimension(cfg)`` the
    filter's n, ``validate(cfg)`` the range checks of ``cfg.model``."""

    schema: type
    build: Callable[[object], MonteCarloData]
    state_dimension: Callable[[object], int]
    validate: Callable[[object], None]
    uses_quadrotor_groups: bool = False


def _positive(key: str, value: float, what: str = "must be > 0") -> None:
    if not (math.isfinite(value) and value > 0):
        raise ConfigError(key, value, what)


def _validate_linear(cfg) -> None:
    m = cfg.model
    _positive("model.acceleration_psd", m.acceleration_psd)
    _positive("model.position_noise_std", m.position_noise_std)
    if not -1 < m.measurement_correlation < 1:
        raise ConfigError("model.measurement_correlation", m.measurement_correlation, "must lie in (-1, 1)")
    for key in ("initial_state", "initial_std"):
        if len(m[key]) != 4:
            raise ConfigError(f"model.{key}", list(m[key]), "must list 4 values (px, py, vx, vy)")
    for i, v in enumerate(m.initial_std):
        _positive(f"model.initial_std[{i}]", v)
    if not -1 / 3 < m.initial_correlation < 1:
        raise ConfigError("model.initial_correlation", m.initial_correlation, "must lie in (-1/3, 1) for n=4")


def _validate_ungm(cfg) -> None:
    m = cfg.model
    _positive("model.Q", m.Q, "must be > 0 (process noise variance)")
    _positive("model.R", m.R, "must be > 0 (measurement noise variance)")
    _positive("model.P0", m.P0, "must be > 0 (initial variance of the filters)")
    if not (math.isfinite(m.x0_var) and m.x0_var >= 0):
        raise ConfigError("model.x0_var", m.x0_var, "must be >= 0 (0: a deterministic initial state)")


def model_specs() -> dict[str, ModelSpec]:
    from quadest.config.validate import validate_quadrotor
    from quadest.models.validation import build_linear_data, build_ungm_data

    return {
        "quadrotor": ModelSpec(
            QuadrotorModelConf,
            build_quadrotor_data,
            lambda cfg: 6 if cfg.model.formulation == "thesis" else 9,
            validate_quadrotor,
            True,
        ),
        "linear": ModelSpec(LinearModelConf, build_linear_data, lambda cfg: 4, _validate_linear),
        "ungm": ModelSpec(UNGMModelConf, build_ungm_data, lambda cfg: 1, _validate_ungm),
    }


def build_data(cfg) -> MonteCarloData:
    """Monte Carlo data of the configured model."""
    return model_specs()[cfg.model.name].build(cfg)
