"""What a ``model=`` option is: one :class:`ModelSpec`, registered once (docs/models.md).

A model option is its config schema, the dimension of its filter's (error) state, its range
checks, its Monte Carlo data builder and whether the PCRLB of its filter model bounds the
filters' MSE. The builder, the checks and the state dimension take the job's typed
:class:`~quadest.config.settings.DataSettings` (``settings.model`` an instance of the spec's
``schema``), never the raw config: the application layer converts it once
(:mod:`quadest.app.settings`). The registry (:mod:`quadest.simulation.registry`) finds the
package's own specs in the modules of :mod:`quadest.simulation` and a plugin's through the entry-point group
``quadest.models``; everything else (the ``/schema/model/<name>`` config store, the pre-run
checks, the PCRLB caption) reads the spec.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from quadest.config.settings import DataSettings
from quadest.montecarlo import MonteCarloData


def _no_checks(settings: DataSettings) -> None:
    """A model without range checks beyond its schema's types."""


@dataclass(frozen=True)
class ModelSpec:
    """One ``model=<name>`` option.

    Attributes:
        name: the option's name: ``model.name`` and the YAML ``conf/model/<name>.yaml``.
        schema: the dataclass of the ``model`` node, stored as ``/schema/model/<name>`` (the
            YAML's default); it must have a ``name`` field.
        build: ``build(settings) -> MonteCarloData``, the data of ``settings.runs`` runs
            (``settings`` a :class:`~quadest.config.settings.DataSettings`: a builder reads the
            Monte Carlo settings, the model, and the sensors and scenario it flies).
        state_dimension: ``state_dimension(settings) -> int``, the dimension of the filter's error
            state (``n_err``; ``n`` for vector states), against which estimator parameters are
            checked before any work (the UT's ``n + λ > 0``).
        validate: ``validate(settings)`` raises :class:`~quadest.errors.ConfigError` naming the key of
            the first value out of range (the schema already checks types and keys).
        uses_quadrotor_groups: the data flies the shared quadrotor, so the ``sensor`` and
            ``scenario`` groups are checked too.
        pcrlb_is_bound: the truth is drawn from the filter model itself with its own noise, so the
            posterior Cramér–Rao recursion (:mod:`quadest.evaluation.pcrlb`) is a true floor on
            the MSE; otherwise it is reported as a reference only. For a model whose truth is a
            setting, a function of the data's ``labels`` (``MonteCarloData.labels``) saying it.
        job_defaults: the model's own values of the job keys :data:`JOB_DEFAULT_KEYS`
            (``duration``, ``sample_period``, ``divergence_bound``), used where neither an experiment
            nor the command line sets them (``conf/config.yaml`` reads them through the
            ``model_default`` resolver); a key left out keeps the job's default.
    """

    name: str
    schema: type
    build: Callable[[DataSettings], MonteCarloData]
    state_dimension: Callable[[DataSettings], int]
    validate: Callable[[DataSettings], None] = _no_checks
    uses_quadrotor_groups: bool = False
    pcrlb_is_bound: bool | Callable[[Mapping[str, Any]], bool] = False
    job_defaults: Mapping[str, float] = dataclasses.field(default_factory=dict)


JOB_DEFAULT_KEYS = ("duration", "sample_period", "divergence_bound")
"""The job keys a model may give its own default for (:attr:`ModelSpec.job_defaults`)."""


def spec_problems(spec: object) -> list[str]:
    """What keeps ``spec`` from being a usable model option (empty when it is one)."""
    if not isinstance(spec, ModelSpec):
        return [f"{spec!r} is not a quadest.simulation.spec.ModelSpec"]
    problems = []
    if not (isinstance(spec.schema, type) and dataclasses.is_dataclass(spec.schema)):
        problems.append("its schema must be a dataclass")
    elif "name" not in {f.name for f in dataclasses.fields(spec.schema)}:
        problems.append("its schema must have a 'name' field")
    for member in ("build", "state_dimension", "validate"):
        if not callable(getattr(spec, member)):
            problems.append(f"its {member} must be callable")
    for key, value in dict(spec.job_defaults).items():
        if key not in JOB_DEFAULT_KEYS:
            problems.append(f"its job_defaults key {key!r} is not one of {list(JOB_DEFAULT_KEYS)}")
        elif not (isinstance(value, int | float) and not isinstance(value, bool) and value > 0):
            problems.append(f"its job_defaults.{key} must be a number > 0, got {value!r}")
    return problems
