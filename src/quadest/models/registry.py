"""The ``model`` config group: each option's schema, data builder, state dimension and checks."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from quadest.config.schema import (
    LinearModelConf,
    QuadrotorModelConf,
    Seed001RatesModelConf,
    UNGMModelConf,
    UPFBenchmarkModelConf,
)
from quadest.models.config_checks import validate_linear, validate_quadrotor, validate_ungm
from quadest.models.quadrotor import QuadrotorFilterModel
from quadest.models.quadrotor_data import build_quadrotor_data
from quadest.models.seed001_rates import build_seed001_rates_data, validate_seed001_rates
from quadest.models.upf_benchmark import build_upf_benchmark_data, validate_upf_benchmark
from quadest.models.validation import build_linear_data, build_ungm_data
from quadest.montecarlo import MonteCarloData


@dataclass(frozen=True)
class ModelSpec:
    """A model option: ``build(cfg)`` makes the Monte Carlo data, ``state_dimension(cfg)`` the
    filter's n, ``validate(cfg)`` the range checks of ``cfg.model``."""

    schema: type
    build: Callable[[object], MonteCarloData]
    state_dimension: Callable[[object], int]
    validate: Callable[[object], None]
    uses_quadrotor_groups: bool = False


def model_specs() -> dict[str, ModelSpec]:
    return {
        "quadrotor": ModelSpec(
            QuadrotorModelConf,
            build_quadrotor_data,
            lambda cfg: len(QuadrotorFilterModel.formulation_state_names(cfg.model.formulation)),
            validate_quadrotor,
            True,
        ),
        "linear": ModelSpec(LinearModelConf, build_linear_data, lambda cfg: 4, validate_linear),
        "ungm": ModelSpec(UNGMModelConf, build_ungm_data, lambda cfg: 1, validate_ungm),
        "upf_benchmark": ModelSpec(
            UPFBenchmarkModelConf, build_upf_benchmark_data, lambda cfg: 1, validate_upf_benchmark
        ),
        "seed001_rates": ModelSpec(
            Seed001RatesModelConf, build_seed001_rates_data, lambda cfg: 3, validate_seed001_rates, True
        ),
    }


def state_dimension(cfg) -> int:
    """State dimension of the configured filter model."""
    return model_specs()[cfg.model.name].state_dimension(cfg)


def build_data(cfg) -> MonteCarloData:
    """Monte Carlo data of the configured model."""
    return model_specs()[cfg.model.name].build(cfg)
