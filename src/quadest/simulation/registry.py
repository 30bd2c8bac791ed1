"""The ``model`` config group: every option's :class:`~quadest.simulation.spec.ModelSpec`, found
once, and the data of the configured one.

Two sources behind the same contract (docs/models.md), as for estimators (docs/plugins.md):

1. **In the repository**: any module-level :class:`ModelSpec` in a module of
   :mod:`quadest.simulation` (``MODEL = ModelSpec("pendulum", ...)``). Adding one touches no other
   file: the registry scans the package.
2. **From an installed package**: an entry point in the group ``quadest.models`` whose name is the
   option's name and whose value is its spec (``"pendulum = mypkg.pendulum:MODEL"``).

A plugin that fails to import, is not a usable spec, is named unlike its entry point or reuses a
built-in name never takes quadest down: it is reported with one line naming the plugin, and
refused if selected (:func:`report_plugin_problems`).
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
from functools import cache

from quadest.config.plugin_entry_points import load_entry_points
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError, PluginError
from quadest.montecarlo import MonteCarloData
from quadest.simulation.spec import ModelSpec, spec_problems

ENTRY_POINT_GROUP = "quadest.models"


def _builtin_specs() -> dict[str, ModelSpec]:
    import quadest.simulation as package

    specs: dict[str, ModelSpec] = {}
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        for value in vars(module).values():
            if isinstance(value, ModelSpec) and not spec_problems(value):
                if specs.get(value.name, value) is not value:
                    raise RuntimeError(f"two built-in models are named {value.name!r}")
                specs[value.name] = value
    return specs


@cache
def discover() -> tuple[dict[str, ModelSpec], dict[str, str]]:
    """All usable model options by name, and one-line problems of the plugins that are not."""
    return load_entry_points(
        ENTRY_POINT_GROUP, "model", dict(sorted(_builtin_specs().items())), spec_problems, lambda spec: spec.name
    )


def model_specs() -> dict[str, ModelSpec]:
    """Every usable model option by name: the package's own and the installed plugins'."""
    return discover()[0]


_warned: set[str] = set()


def report_plugin_problems(selected: str) -> None:
    """Refuse the selected model if it is a broken plugin; mention the other broken plugins once
    per process on stderr."""
    specs, problems = discover()
    for name, message in problems.items():
        if name == selected and name not in specs:
            raise PluginError(name, message, key="model.name")
        if message not in _warned:
            _warned.add(message)
            print(f"quadest: warning: {message}", file=sys.stderr)


def model_spec(name: str) -> ModelSpec:
    """The spec of option ``model.name`` = ``name``.

    Raises:
        ConfigError: an unknown name (the message lists the options), or a broken plugin's.
    """
    report_plugin_problems(name)
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
