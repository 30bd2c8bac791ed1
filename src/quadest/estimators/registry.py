"""Finding estimators and building them from config nodes.

Three sources, all behind the same contract (``docs/plugins.md``):

1. **In the repository**: any class in a module of :mod:`quadest.estimators` that subclasses
   :class:`Estimator` or :class:`SingleRunEstimator` and sets ``config_name`` and ``Params``.
   Adding one touches no other file: the registry scans the package.
2. **From an installed package**: an entry point in the group ``quadest.estimators`` whose name
   is the config name and whose value is the class (``"ckf2 = mypkg.filters:CKF2"``).
3. **From a config only**: an ``estimator.<label>`` node with ``_target_`` naming any importable
   class that meets the contract.

The first two are found by the one registry of every extension kind
(:mod:`quadest.config.registry`): an estimator of either that fails to import, breaks the
contract or shares its name with another never takes quadest down; it is reported with one line
naming it and the reason, and refused if selected.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from functools import cache
from types import ModuleType
from typing import Any

from quadest.config.registry import ExtensionKind, Found, scan
from quadest.errors import ConfigError
from quadest.estimators.base import CAPABILITIES, Estimator, PerRunAdapter, SingleRunEstimator
from quadest.estimators.params import RESERVED_KEYS
from quadest.estimators.smoother_settings import with_smoother_keys
from quadest.models.base import FilterModel

ENTRY_POINT_GROUP = "quadest.estimators"


@dataclass(frozen=True)
class EstimatorSpec:
    """A registered estimator: its class, its config schema (the ``Params`` dataclass plus the
    reserved smoother keys, :func:`~quadest.estimators.smoother_settings.with_smoother_keys`), and
    where it is from."""

    name: str
    cls: type
    params: type
    source: str


def contract_problems(cls: Any) -> list[str]:
    """What keeps ``cls`` from meeting the estimator contract (empty when it does)."""
    if not inspect.isclass(cls):
        return [f"{cls!r} is not a class"]
    if not issubclass(cls, Estimator | SingleRunEstimator):
        return ["it must subclass quadest.estimators.Estimator (batched) or SingleRunEstimator (one run)"]
    problems = []
    if inspect.isabstract(cls):
        missing = sorted(getattr(cls, "__abstractmethods__", ()))
        problems.append(f"it does not implement {', '.join(missing)}")
    unknown = set(getattr(cls, "capabilities", frozenset())) - CAPABILITIES
    if unknown:
        problems.append(f"unknown capabilities {sorted(unknown)}; known: {sorted(CAPABILITIES)}")
    params = getattr(cls, "Params", None)
    if params is not None and not dataclasses.is_dataclass(params):
        problems.append("its Params must be a dataclass")
    return problems


def registry_problems(cls: Any) -> list[str]:
    """What keeps ``cls`` from being a registered estimator: the contract, and a ``Params``
    dataclass (only a ``_target_`` class may go without one)."""
    problems = contract_problems(cls)
    if getattr(cls, "Params", None) is None:
        problems.append("it must define Params, the dataclass of its config parameters")
    return problems


def _declared(module: ModuleType) -> Iterator[tuple[str, str, type]]:
    """The classes ``module`` defines that set their own ``config_name``."""
    for attribute, cls in inspect.getmembers(module, inspect.isclass):
        name = cls.__dict__.get("config_name")
        if cls.__module__ == module.__name__ and name:
            yield name, attribute, cls


ESTIMATORS = ExtensionKind(
    kind="estimator",
    package="quadest.estimators",
    group=ENTRY_POINT_GROUP,
    declared=_declared,
    problems_of=registry_problems,
    make=lambda name, cls, origin: EstimatorSpec(name, cls, with_smoother_keys(cls.Params), origin),
)


@cache
def discover() -> Found:
    """Every estimator, the package's own and the installed plugins', with the one-line problems
    of those refused (:mod:`quadest.config.registry`)."""
    return scan(ESTIMATORS)


def estimator_specs() -> dict[str, EstimatorSpec]:
    """Every usable estimator by config name: the package's own and the installed plugins'."""
    return discover().usable


def builtin_estimators() -> dict[str, EstimatorSpec]:
    """The package's own usable estimators by config name, without any installed plugin."""
    return discover().builtins()


def estimator_parameters(node: Mapping[str, Any]) -> dict[str, Any]:
    """The constructor keyword arguments of an estimator config node."""
    return {k: v for k, v in node.items() if k not in RESERVED_KEYS}


def resolve(label: str, node: Mapping[str, Any]) -> tuple[type, dict[str, Any]]:
    """The class and checked parameters of config node ``estimator.<label>``.

    Raises:
        ConfigError: unknown kind, a ``_target_`` that is not an importable class meeting the
            contract, or parameters the estimator does not take.
    """
    params = estimator_parameters(node)
    if "_target_" in node:
        target = node["_target_"]
        try:
            module, _, attr = str(target).rpartition(".")
            cls = getattr(importlib.import_module(module), attr)
        except Exception as exc:
            raise ConfigError(
                f"estimator.{label}._target_", target, f"an importable class ({type(exc).__name__}: {exc})"
            ) from None
        issues = contract_problems(cls)
        if issues:
            raise ConfigError(
                f"estimator.{label}._target_",
                target,
                f"a class meeting the estimator contract (docs/plugins.md): {'; '.join(issues)}",
            )
        schema = getattr(cls, "Params", None)
    else:
        found = discover()
        kind = node.get("kind", label)
        if kind not in found.usable:
            allowed = found.problems.get(kind, f"one of {sorted(found.usable)}")
            raise ConfigError(f"estimator.{label}.kind", kind, allowed)
        cls, schema = found.usable[kind].cls, found.usable[kind].params
    if schema is not None:
        fields = {f.name for f in dataclasses.fields(schema)} - set(RESERVED_KEYS)
        unknown = sorted(set(params) - fields)
        if unknown:
            raise ConfigError(
                f"estimator.{label}.{unknown[0]}",
                params[unknown[0]],
                f"{cls.__name__} takes {sorted(fields) or 'no parameters'}",
            )
    return cls, params


def make_estimator(cls: type, model: FilterModel, params: Mapping[str, Any]) -> Estimator:
    """An instance behind the batched interface: a batch-capable class directly, a single-run
    class wrapped in :class:`PerRunAdapter`."""
    if issubclass(cls, Estimator):
        return cls(model, **params)
    return PerRunAdapter(model, cls, **params)


def build_estimator(label: str, node: Mapping[str, Any], model: FilterModel) -> Estimator:
    """Construct the estimator of config node ``estimator.<label>`` for a model bound to a batch."""
    cls, params = resolve(label, node)
    return make_estimator(cls, model, params)
