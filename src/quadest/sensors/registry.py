"""Finding further sensors (:class:`~quadest.sensors.base.Sensor`), as estimators and models are
found (docs/sensors.md):

1. **In the repository**: any :class:`Sensor` subclass defined in a module of
   :mod:`quadest.sensors` that sets ``config_name``. Adding one touches no other file.
2. **From an installed package**: an entry point in the group ``quadest.sensors`` whose name is
   the sensor's ``config_name`` and whose value is the class
   (``"rangefinder = mypkg.rangefinder:Rangefinder"``).

A plugin that fails to import, breaks the contract, is named unlike its entry point or reuses a
built-in name never takes quadest down: it is reported with one line naming the plugin, and
refused if selected.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from functools import cache

from quadest.config.plugin_entry_points import load_entry_points
from quadest.sensors.base import Sensor, sensor_problems

ENTRY_POINT_GROUP = "quadest.sensors"


def _builtin_sensors() -> dict[str, type[Sensor]]:
    import quadest.sensors as package

    found: dict[str, type[Sensor]] = {}
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ == module.__name__ and "config_name" in cls.__dict__ and not sensor_problems(cls):
                if found.setdefault(cls.config_name, cls) is not cls:
                    raise RuntimeError(f"two built-in sensors are named {cls.config_name!r}")
    return found


@cache
def discover() -> tuple[dict[str, type[Sensor]], dict[str, str]]:
    """All usable sensors by name, and one-line problems of the plugins that are not."""
    return load_entry_points(
        ENTRY_POINT_GROUP,
        "sensor",
        dict(sorted(_builtin_sensors().items())),
        sensor_problems,
        lambda cls: cls.config_name,
    )


def sensor_classes() -> dict[str, type[Sensor]]:
    """Every usable sensor by name: the package's own and the installed plugins'."""
    return discover()[0]


def is_builtin(cls: type[Sensor]) -> bool:
    """Whether ``cls`` is one of quadest's own sensors (it may draw from the streams of
    :data:`quadest.montecarlo.streams.STREAMS` it names; a plugin's are all named after it)."""
    return cls.__module__.startswith("quadest.")
