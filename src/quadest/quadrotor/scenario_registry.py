"""Finding scenarios (:class:`~quadest.quadrotor.scenarios.Scenario`), as estimators, models and
sensors are found (docs/scenarios.md):

1. **In the repository**: any :class:`Scenario` subclass defined in a module of
   :mod:`quadest.quadrotor` that sets its own ``name`` (``name: str = "climb"``). Adding one
   touches no other file.
2. **From an installed package**: an entry point in the group ``quadest.scenarios`` whose name is
   the scenario's ``name`` and whose value is the class (``"climb = mypkg.climb:Climb"``).

Both are found by the one registry of every extension kind (:mod:`quadest.config.registry`): a
scenario of either that fails to import, breaks the contract, is named unlike its entry point or
shares its name with another never takes quadest down; it is reported with one line naming it
and the reason, and refused if selected.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Iterator
from functools import cache
from types import ModuleType
from typing import Any

from quadest.config.registry import ExtensionKind, Found, scan
from quadest.quadrotor.scenarios import Scenario

ENTRY_POINT_GROUP = "quadest.scenarios"


def scenario_problems(cls: Any) -> list[str]:
    """What keeps ``cls`` from being a usable scenario (empty when it is one)."""
    if not inspect.isclass(cls) or not issubclass(cls, Scenario):
        return [f"{cls!r} must subclass quadest.quadrotor.scenarios.Scenario"]
    problems = []
    if "name" not in cls.__dict__ or not isinstance(cls.name, str):
        problems.append("it must set name, the scenario's name, as a str")
    if not dataclasses.is_dataclass(cls) or "__dataclass_fields__" not in cls.__dict__:
        problems.append("it must be a dataclass (its fields are the scenario node's keys)")
    return problems


def _declared(module: ModuleType) -> Iterator[tuple[str, str, type]]:
    """The :class:`Scenario` subclasses ``module`` defines that set their own ``name``."""
    for attribute, cls in inspect.getmembers(module, inspect.isclass):
        if issubclass(cls, Scenario) and cls is not Scenario and cls.__module__ == module.__name__:
            if "name" in cls.__dict__:
                yield cls.name, attribute, cls


SCENARIOS = ExtensionKind(
    kind="scenario",
    package="quadest.quadrotor",
    group=ENTRY_POINT_GROUP,
    declared=_declared,
    problems_of=scenario_problems,
    name_of=lambda cls: cls.name,
)


@cache
def discover() -> Found:
    """Every scenario, the package's own and the installed plugins', with the one-line problems
    of those refused (:mod:`quadest.config.registry`)."""
    return scan(SCENARIOS)


def scenario_classes() -> dict[str, type[Scenario]]:
    """Every usable scenario by name: the package's own and the installed plugins'."""
    return discover().usable


def builtin_scenario_classes() -> dict[str, type[Scenario]]:
    """The package's own usable scenarios by name, without any installed plugin."""
    return discover().builtins()
