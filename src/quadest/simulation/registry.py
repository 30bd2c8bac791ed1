"""The ``model`` config group: each option's schema, data builder, state dimension and checks."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from quadest.models.config_checks import validate_linear, validate_quadrotor, validate_ungm
from quadest.models.quadrotor import QuadrotorFilterModel
from quadest.models.schemas import (
    AttitudeModelConf,
    InsModelConf,
    LinearModelConf,
    QuadrotorModelConf,
    Seed001RatesModelConf,
    Seed003AttitudeModelConf,
    UNGMModelConf,
    UPFBenchmarkModelConf,
)
from quadest.models.seed001_rates import validate_seed001_rates
from quadest.models.seed003_attitude import validate_seed003_attitude
from quadest.models.upf_benchmark import validate_upf_benchmark
from quadest.montecarlo import MonteCarloData
from quadest.simulation.attitude_data import build_attitude_data, validate_attitude
from quadest.simulation.ins_data import build_ins_data, validate_ins
from quadest.simulation.quadrotor_data import build_quadrotor_data
from quadest.simulation.seed001_rates_data import build_seed001_rates_data
from quadest.simulation.seed003_attitude_data import build_seed003_attitude_data
from quadest.simulation.upf_benchmark_data import build_upf_benchmark_data
from quadest.simulation.validation_data import build_linear_data, build_ungm_data


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
        "seed003_attitude": ModelSpec(
            Seed003AttitudeModelConf, build_seed003_attitude_data, lambda cfg: 5, validate_seed003_attitude, True
        ),
        "attitude": ModelSpec(AttitudeModelConf, build_attitude_data, lambda cfg: 9, validate_attitude, True),  # n_err
        "ins": ModelSpec(InsModelConf, build_ins_data, lambda cfg: 15, validate_ins, True),  # n_err
    }


def state_dimension(cfg) -> int:
    """State dimension of the configured filter model."""
    return model_specs()[cfg.model.name].state_dimension(cfg)


def build_data(cfg) -> MonteCarloData:
    """Monte Carlo data of the configured model: simulated, or replayed from ``source`` (a flight log)."""
    if cfg.get("source") is not None:
        from quadest.replay.data import build_replay_data  # docs/replay.md

        return build_replay_data(cfg)
    return model_specs()[cfg.model.name].build(cfg)
