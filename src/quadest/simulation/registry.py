"""The ``model`` config group: every option's :class:`~quadest.simulation.spec.ModelSpec`, found
once, and the data of the configured one.

Two sources behind the same contract (docs/models.md), as for estimators (docs/plugins.md):

1. **In the repository**: any module-level :class:`ModelSpec` in a module of
   :mod:`quadest.simulation` (``MODEL = ModelSpec("pendulum", ...)``). Adding one touches no other
   file: the registry scans the package.
2. **From an installed package**: an entry point in the group ``quadest.models`` whose name is the
   option's name and whose value is its spec (``"pendulum = mypkg.pendulum:MODEL"``).

Both are found by the one registry of every extension kind (:mod:`quadest.config.registry`): a
model of either that fails to import, is not a usable spec, is named unlike its entry point or
shares its name with another never takes quadest down; it is reported with one line naming it
and the reason, and refused if selected.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import cache
from types import ModuleType

from quadest.config.registry import ExtensionKind, Found, scan
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.montecarlo import MonteCarloData
from quadest.simulation.spec import ModelSpec, spec_problems

ENTRY_POINT_GROUP = "quadest.models"


def _declared(module: ModuleType) -> Iterator[tuple[str, str, ModelSpec]]:
    """The module-level model specs of ``module``."""
    for attribute, value in vars(module).items():
        if isinstance(value, ModelSpec):
            yield value.name, attribute, value


MODELS = ExtensionKind(
    kind="model",
    package="quadest.simulation",
    group=ENTRY_POINT_GROUP,
    declared=_declared,
    problems_of=spec_problems,
    name_of=lambda spec: spec.name,
)


@cache
def discover() -> Found:
    """Every model option, the package's own and the installed plugins', with the one-line
    problems of those refused (:mod:`quadest.config.registry`)."""
    return scan(MODELS)


def model_specs() -> dict[str, ModelSpec]:
    """Every usable model option by name: the package's own and the installed plugins'."""
    return discover().usable


def builtin_model_specs() -> dict[str, ModelSpec]:
    """The package's own usable model options by name, without any installed plugin."""
    return discover().builtins()


def model_spec(name: str) -> ModelSpec:
    """The spec of option ``model.name`` = ``name``.

    Raises:
        ConfigError: an unknown name (the message lists the options), or a broken plugin's.
    """
    discover().refuse_selected([name], key="model.name")
    specs = model_specs()
    if name not in specs:
        raise ConfigError("model.name", name, f"one of {sorted(specs)}")
    return specs[name]


def state_dimension(settings: DataSettings) -> int:
    """State dimension of the configured filter model."""
    return model_spec(settings.model.name).state_dimension(settings)


def build_data(settings: DataSettings) -> MonteCarloData:
    """Monte Carlo data of the configured model: simulated, or replayed from ``source`` (a flight log)."""
    if settings.source is not None:
        from quadest.replay.data import build_replay_data  # docs/replay.md

        return build_replay_data(settings)
    return model_spec(settings.model.name).build(settings)
