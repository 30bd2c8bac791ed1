"""Finding further sensors (:class:`~quadest.sensors.base.Sensor`), as estimators and models are
found (docs/sensors.md):

1. **In the repository**: any :class:`Sensor` subclass defined in a module of
   :mod:`quadest.sensors` that sets ``config_name``. Adding one touches no other file.
2. **From an installed package**: an entry point in the group ``quadest.sensors`` whose name is
   the sensor's ``config_name`` and whose value is the class
   (``"rangefinder = mypkg.rangefinder:Rangefinder"``).

Both are found by the one registry of every extension kind (:mod:`quadest.config.registry`): a
sensor of either that fails to import, breaks the contract, is named unlike its entry point or
shares its name with another never takes quadest down; it is reported with one line naming it
and the reason, and refused if selected.
"""

from __future__ import annotations

import inspect
from collections.abc import Iterator
from functools import cache
from types import ModuleType

from quadest.config.registry import ExtensionKind, Found, scan
from quadest.sensors.base import Sensor, sensor_problems

ENTRY_POINT_GROUP = "quadest.sensors"


def _declared(module: ModuleType) -> Iterator[tuple[str, str, type]]:
    """The classes ``module`` defines that set their own ``config_name``."""
    for attribute, cls in inspect.getmembers(module, inspect.isclass):
        if cls.__module__ == module.__name__ and "config_name" in cls.__dict__:
            yield cls.config_name, attribute, cls


SENSORS = ExtensionKind(
    kind="sensor",
    package="quadest.sensors",
    group=ENTRY_POINT_GROUP,
    declared=_declared,
    problems_of=sensor_problems,
    name_of=lambda cls: cls.config_name,
)


@cache
def discover() -> Found:
    """Every sensor, the package's own and the installed plugins', with the one-line problems of
    those refused (:mod:`quadest.config.registry`)."""
    return scan(SENSORS)


def sensor_classes() -> dict[str, type[Sensor]]:
    """Every usable sensor by name: the package's own and the installed plugins'."""
    return discover().usable


def builtin_sensor_classes() -> dict[str, type[Sensor]]:
    """The package's own usable sensors by name, without any installed plugin."""
    return discover().builtins()


def is_builtin(cls: type[Sensor]) -> bool:
    """Whether ``cls`` is one of quadest's own sensors (it may draw from the streams of
    :data:`quadest.montecarlo.streams.STREAMS` it names; a plugin's are all named after it)."""
    return cls.__module__.startswith("quadest.")
