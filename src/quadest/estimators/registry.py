"""Name → estimator lookup, and construction of an estimator from its config node."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from quadest.errors import ConfigError
from quadest.estimators.base import Estimator, PerRunAdapter
from quadest.models.base import FilterModel


@dataclass(frozen=True)
class EstimatorSpec:
    """A registered estimator: its class and the dataclass of its config parameters."""

    name: str
    cls: type
    params: type


def builtin_estimators() -> dict[str, EstimatorSpec]:
    """The estimators shipped with quadest, by config name."""
    from quadest.estimators.filterpy_ekf import EKFParams, FilterpyEKF
    from quadest.estimators.filterpy_ukf import FilterpyUKF, UKFParams
    from quadest.estimators.srukf import SRUKF, SRUKFParams

    return {
        "ekf": EstimatorSpec("ekf", FilterpyEKF, EKFParams),
        "ukf": EstimatorSpec("ukf", FilterpyUKF, UKFParams),
        "srukf": EstimatorSpec("srukf", SRUKF, SRUKFParams),
    }


def estimator_parameters(node: Mapping[str, Any]) -> dict[str, Any]:
    """The constructor keyword arguments of an estimator config node (everything but ``kind``)."""
    return {k: v for k, v in node.items() if k != "kind"}


def build_estimator(label: str, node: Mapping[str, Any], model: FilterModel) -> Estimator:
    """Construct the estimator of config node ``estimator.<label>`` for a model bound to a batch.

    A batch-capable class is constructed directly; a single-run class is wrapped in
    :class:`PerRunAdapter`.
    """
    registry = builtin_estimators()
    kind = node.get("kind", label)
    if kind not in registry:
        raise ConfigError(f"estimator.{label}.kind", kind, f"one of {sorted(registry)}")
    spec = registry[kind]
    fields = {f.name for f in dataclasses.fields(spec.params)} - {"kind"}
    params = {k: v for k, v in estimator_parameters(node).items() if k in fields}
    if getattr(spec.cls, "batched", False):
        return spec.cls(model, **params)
    return PerRunAdapter(model, spec.cls, **params)
