"""Finding the metrics, as the estimators are found (``docs/metrics.md``): every class in a module
of :mod:`quadest.metrics` that subclasses :class:`~quadest.metrics.base.Metric` and sets a
``name`` is a metric, so a new metric is one new file; :func:`register` adds one from elsewhere
(a plugin, a notebook). The built-in ones (:data:`quadest.metrics.builtin.BUILT_IN`) come first,
in the order of their columns, then the package's others by module name, then the registered ones.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from functools import cache

from quadest.metrics.base import Metric
from quadest.metrics.builtin import BUILT_IN

_registered: dict[str, Metric] = {}


@cache
def _package_metrics() -> tuple[Metric, ...]:
    import quadest.metrics as package

    found = {m.name: m for m in BUILT_IN}
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda i: i.name):
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if cls.__module__ == module.__name__ and issubclass(cls, Metric) and cls.name and cls.name not in found:
                found[cls.name] = cls()
    return tuple(found.values())


def register(metric: Metric) -> Metric:
    """Add ``metric`` to every job from now on (in this process); its name must be new."""
    if not metric.name or any(m.name == metric.name for m in all_metrics()):
        raise ValueError(f"a metric needs a name that no other metric has, got {metric.name!r}")
    _registered[metric.name] = metric
    return metric


def unregister(name: str) -> None:
    """Remove a metric added with :func:`register`."""
    _registered.pop(name, None)


def all_metrics() -> tuple[Metric, ...]:
    """Every metric, in column order."""
    return (*_package_metrics(), *_registered.values())
