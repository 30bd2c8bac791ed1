"""Estimator parameters that describe themselves: ranges on the ``Params`` dataclass fields.

A field declares what it allows with :func:`ranged`; a ``Params`` class may add constraints that
involve several fields or the state dimension with a static method
``constraints(values: Mapping, n: int) -> list[tuple[key, value, allowed]]``. The pre-run
validation (:func:`parameter_problem`) reads both, so a new estimator's parameters are checked
before any work starts without touching the validation code; the estimator base classes check them
again at every construction (:class:`quadest.estimators.base.Estimator`); and the metrics tables
take their parameter columns from the same fields (:func:`parameter_names`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

SMOOTHER_KEYS = (
    "smoother",
    "smoother_lag",
    "smoother_trajectories",
    "smoother_iterations",
)  # quadest.estimators.smoother_settings
RESERVED_KEYS = ("kind", "_target_", *SMOOTHER_KEYS)  # config keys that are not constructor parameters


@dataclass(frozen=True)
class Range:
    """Allowed values of a numeric parameter: bounds (open or closed) and integrality."""

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    integer: bool = False

    def allows(self, value: Any) -> bool:
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            return False
        if self.integer and value != int(value):
            return False
        return not (
            (self.gt is not None and not value > self.gt)
            or (self.ge is not None and not value >= self.ge)
            or (self.lt is not None and not value < self.lt)
            or (self.le is not None and not value <= self.le)
        )

    def describe(self) -> str:
        bounds = [
            (op, b) for op, b in ((">", self.gt), (">=", self.ge), ("<", self.lt), ("<=", self.le)) if b is not None
        ]
        words = " and ".join(f"{op} {b:g}" for op, b in bounds)
        kind = "an integer" if self.integer else "a finite number"
        return f"must be {kind}" + (f" {words}" if words else "")


def ranged(default: Any, doc: str = "", **bounds: Any) -> Any:
    """A dataclass field with a default, a one-line description and a :class:`Range`
    (keywords ``gt``, ``ge``, ``lt``, ``le``, ``integer``)."""
    return dataclasses.field(default=default, metadata={"range": Range(**bounds), "doc": doc})


def parameter_names(params_cls: type | None) -> tuple[str, ...]:
    """The parameter names of an estimator's ``Params`` (its config keys besides ``kind``)."""
    if params_cls is None or not dataclasses.is_dataclass(params_cls):
        return ()
    return tuple(f.name for f in dataclasses.fields(params_cls) if f.name not in RESERVED_KEYS)


def parameter_problem(params_cls: type | None, values: Mapping[str, Any], n: int) -> tuple[str, Any, str] | None:
    """The first ``(key, value, allowed)`` that ``values`` violate, or ``None``.

    ``values`` are the configured parameters (defaults filled in from ``params_cls``); ``n`` is
    the state dimension of the configured model.
    """
    if params_cls is None or not dataclasses.is_dataclass(params_cls):
        return None
    full = {f.name: f.default for f in dataclasses.fields(params_cls) if f.default is not dataclasses.MISSING}
    full.update(values)
    for f in dataclasses.fields(params_cls):
        rng = f.metadata.get("range")
        if rng is not None and f.name in full and not rng.allows(full[f.name]):
            return f.name, full[f.name], rng.describe() + (f" ({f.metadata['doc']})" if f.metadata.get("doc") else "")
    constraints = getattr(params_cls, "constraints", None)
    if constraints is not None:
        problems = constraints(full, n)
        if problems:
            return problems[0]
    return None


def unscented_constraints(values: Mapping[str, Any], n: int) -> list[tuple[str, Any, str]]:
    """The UT's points are real only when ``n + λ = α² (n + κ) > 0`` (thesis eqs 5.2–5.6), checked in
    floating point exactly as the filter computes it (:func:`quadest.numerics.sigma_points.ut_weights`:
    ``λ = α² (n + κ) − n``, then ``n + λ``). With ``n + κ > 0`` and ``n + λ`` still not > 0, α is too
    small: ``α² (n + κ)`` is lost in the rounding of ``n`` (or underflows), and the key named is alpha.
    An augmented filter's points live in ``n + q + r`` dimensions, which only the model knows: its
    rule checks them when the filter is built (:class:`~quadest.estimators.sigma_point.SigmaPointFilter`)."""
    alpha, kappa = values.get("alpha"), values.get("kappa", 0.0)
    if alpha is None or values.get("augmented"):
        return []
    lam = alpha**2 * (n + kappa) - n
    if n + lam > 0:
        return []
    if not n + kappa > 0:
        return [("kappa", kappa, f"n + lambda = alpha^2 (n + kappa) must be > 0, so kappa > {-n} for n={n}")]
    lost = (
        f"too small: n + lambda = alpha^2 (n + kappa) computes to {n + lam:g} in floating point for n={n}, "
        f"kappa={kappa:g} (alpha^2 (n + kappa) is lost next to n); alpha >= {smallest_alpha(n, kappa):.2g} works"
    )
    return [("alpha", alpha, lost)]


def smallest_alpha(n: int, kappa: float) -> float:
    """An α (two significant digits, rounded up) for which ``n + λ > 0`` in floating point, given
    ``n + κ > 0``: ``α² (n + κ)`` must exceed the spacing of floats at ``n``."""
    alpha = float(f"{math.sqrt(2 * math.ulp(float(n)) / (n + kappa)):.2g}")
    while not n + (alpha**2 * (n + kappa) - n) > 0:
        alpha = float(f"{alpha * 1.1:.2g}")
    return alpha
