"""The smoother keys (``SMOOTHER_KEYS``) every estimator's config node takes, and their checks.

``estimator.<label>.smoother``: ``none`` (default), ``fixed_interval`` (the whole run: the RTS /
unscented RTS smoother of a Gaussian filter, forward-filtering backward-simulation for a particle
filter), ``fixed_lag`` (Gaussian filters only: each state given the measurements up to
``smoother_lag`` samples later) or ``iterated`` (the filters of
:mod:`quadest.estimators.iterated`: the whole run re-linearised ``smoother_iterations`` times about
its smoothed trajectory, started from the filter's output: the IERTS and the IPLS).
``smoother_trajectories`` is the number of backward trajectories of the particle smoother (cost
``O(N · M)`` per step). The keys are reserved: they are not the
estimator's constructor parameters and not its parameter columns; the job reads them here.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

from quadest.errors import ConfigError
from quadest.estimators.params import SMOOTHER_KEYS

SMOOTHERS = ("none", "fixed_interval", "fixed_lag", "iterated")
DEFAULT_LAG = 10
DEFAULT_TRAJECTORIES = 100
DEFAULT_ITERATIONS = 10


@dataclass(frozen=True)
class SmootherSettings:
    """A requested smoother: ``kind`` (``fixed_interval``, ``fixed_lag`` or ``iterated``), the lag
    in samples, the particle smoother's number of backward trajectories and the iterated
    smoother's number of re-linearisations."""

    kind: str
    lag: int = DEFAULT_LAG
    trajectories: int = DEFAULT_TRAJECTORIES
    iterations: int = DEFAULT_ITERATIONS

    @property
    def label_suffix(self) -> str:
        """What the smoothed row's name adds to the estimator's label: ``+smoothed`` for the
        whole run (fixed interval or iterated), ``+lag<L>`` for a fixed lag."""
        return f"+lag{self.lag}" if self.kind == "fixed_lag" else "+smoothed"


def _count(key: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ConfigError(key, value, "an integer >= 1")
    return int(value)


def smoother_settings(label: str, node: Mapping[str, Any], cls: type) -> SmootherSettings | None:
    """The smoother asked for by config node ``estimator.<label>`` of class ``cls``, or ``None``.

    Raises:
        ConfigError: an unknown smoother, a lag or trajectory count that is not a positive integer,
            or a smoother the estimator cannot give (no smoothing capability; a fixed lag of a
            particle filter).
    """
    kind = node.get("smoother", "none")
    if kind is None:
        kind = "none"
    if kind not in SMOOTHERS:
        raise ConfigError(f"estimator.{label}.smoother", kind, f"one of {list(SMOOTHERS)}")
    lag = _count(f"estimator.{label}.smoother_lag", node.get("smoother_lag", DEFAULT_LAG))
    trajectories = _count(
        f"estimator.{label}.smoother_trajectories", node.get("smoother_trajectories", DEFAULT_TRAJECTORIES)
    )
    iterations = _count(f"estimator.{label}.smoother_iterations", node.get("smoother_iterations", DEFAULT_ITERATIONS))
    if kind == "none":
        return None
    capabilities = set(getattr(cls, "capabilities", frozenset()))
    if "smoothing" not in capabilities and "particle_smoothing" not in capabilities:
        raise ConfigError(
            f"estimator.{label}.smoother",
            kind,
            "none: this estimator keeps no smoother steps (smoothers: ekf, ukf, mekf, hf, the sigma-point "
            "family, the particle filters; docs/smoothers.md)",
        )
    if kind == "fixed_lag" and "smoothing" not in capabilities:
        raise ConfigError(
            f"estimator.{label}.smoother", kind, "fixed_interval or none: a particle filter's smoother is FFBSi"
        )
    if kind == "iterated" and "iterated_smoothing" not in capabilities:
        raise ConfigError(
            f"estimator.{label}.smoother",
            kind,
            "none, fixed_interval or fixed_lag: only iekf and iplf re-linearise the whole run (docs/smoothers.md)",
        )
    return SmootherSettings(kind, lag, trajectories, iterations)


_PREFIX = "SmootherSchema"


@cache
def with_smoother_keys(params: type) -> type:
    """The config schema of an estimator: its ``Params`` dataclass plus the reserved smoother keys
    (a subclass, so Hydra types the node and refuses unknown keys). It is an attribute of this
    module under a name that encodes ``params``' module and name, so it pickles (worker processes,
    launchers) and unpickles in a process that has not built it yet (:func:`__getattr__`)."""
    schema = dataclasses.make_dataclass(
        params.__name__,
        [
            (key, type(default), dataclasses.field(default=default))
            for key, default in zip(
                SMOOTHER_KEYS, ("none", DEFAULT_LAG, DEFAULT_TRAJECTORIES, DEFAULT_ITERATIONS), strict=True
            )
        ],
        bases=(params,),
    )
    schema.__module__ = __name__
    schema.__qualname__ = "__".join([_PREFIX, *params.__module__.split("."), params.__qualname__])
    return schema


def __getattr__(name: str) -> type:
    """The schema :func:`with_smoother_keys` made for the ``Params`` its ``name`` encodes."""
    parts = name.split("__")
    if len(parts) < 3 or parts[0] != _PREFIX:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    params = getattr(importlib.import_module(".".join(parts[1:-1])), parts[-1])
    return with_smoother_keys(params)
