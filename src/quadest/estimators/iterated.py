"""The iterated extended Kalman filter (``iekf``) and the iterated posterior-linearisation filter
(``iplf``): :class:`~quadest.estimators.gaussian_filter.GaussianFilter` with an iterated
integration (:mod:`quadest.estimators.integrations`), batched over Monte Carlo runs.

- ``iekf``: Taylor linearisation re-done at each iterate of the mean (Gauss–Newton on the MAP
  estimate; Bell & Cathey 1993; Särkkä & Svensson 2023, Algorithm 7.9). ``iterations: 1`` is the EKF.
- ``iplf``: statistical linear regression re-done about the current posterior with a sigma-point
  rule (García-Fernández et al. 2015; Särkkä & Svensson 2023, Algorithm 10.11). ``iterations: 1``
  is the rule's sigma-point filter (the UKF, CKF, GHKF, ...).

Both take a smoother: ``smoother: fixed_interval`` (the RTS smoother of the same linearisation)
or ``smoother: iterated`` (the IERTS / the IPLS, :mod:`quadest.estimators.iterated_smoothing`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from quadest.estimators.gaussian_filter import GaussianFilter
from quadest.estimators.integrations import Integration, StatisticalLinearRegression, Taylor
from quadest.estimators.params import ranged, unscented_constraints
from quadest.models.base import FilterModel
from quadest.numerics.rules import (
    CentralDifferenceRule,
    CubatureRule,
    FifthDegreeCubatureRule,
    GaussHermiteRule,
    IntegrationRule,
    UnscentedRule,
)

RULES = ("gauss_hermite", "unscented", "cubature", "cubature5", "central_difference")


@dataclass
class IEKFParams:
    """Configuration of ``estimator=iekf``."""

    kind: str = "iekf"
    iterations: int = ranged(10, "Gauss-Newton iterations of each measurement update (1: the EKF)", ge=1, integer=True)
    tolerance: float = ranged(0.0, "stop a run's iterations once its mean moves by no more (max-norm)", ge=0.0)


@dataclass
class IPLFParams:
    """Configuration of ``estimator=iplf``: the rule and its parameters (``p`` for Gauss–Hermite,
    ``alpha``/``beta``/``kappa`` for the unscented rule, ``h`` for central differences)."""

    kind: str = "iplf"
    rule: str = "cubature"
    p: int = ranged(3, "Gauss-Hermite points per dimension (p^n in all)", ge=1, integer=True)
    alpha: float = ranged(1.0, "unscented rule: spread of the sigma points", gt=0.0)
    beta: float = ranged(0.0, "unscented rule: prior knowledge of the distribution (2: Gaussian)")
    kappa: float = ranged(0.0, "unscented rule: secondary scaling")
    h: float = ranged(3.0**0.5, "central differences: step (h^2 = 3 is optimal for a Gaussian)", ge=1.0)
    iterations: int = ranged(
        10, "posterior linearisations of each measurement update (1: the SLR filter)", ge=1, integer=True
    )
    tolerance: float = ranged(0.0, "stop a run's iterations once its mean moves by no more (max-norm)", ge=0.0)

    @staticmethod
    def constraints(values: Mapping[str, Any], n: int) -> list[tuple[str, Any, str]]:
        """A known rule; the unscented rule's real points (``n + λ > 0``) when it is selected; a
        Gauss–Hermite grid of at most its maximum number of points in the model's dimension."""
        rule = values.get("rule")
        if rule not in RULES:
            return [("rule", rule, f"one of {list(RULES)}")]
        if rule == "unscented":
            return unscented_constraints(values, n)
        if rule == "gauss_hermite" and n > 0:
            why = GaussHermiteRule(int(values.get("p", 3))).size_problem(n)
            if why is not None:
                return [("p", values.get("p", 3), f"{why} or take rule: cubature")]
        return []


def integration_rule(
    rule: str, p: int = 3, alpha: float = 1.0, beta: float = 0.0, kappa: float = 0.0, h: float = 3.0**0.5
) -> IntegrationRule:
    """The sigma-point rule named ``rule`` (one of :data:`RULES`) with its parameters."""
    if rule == "gauss_hermite":
        return GaussHermiteRule(int(p))
    if rule == "unscented":
        return UnscentedRule(float(alpha), float(beta), float(kappa))
    if rule == "cubature":
        return CubatureRule()
    if rule == "cubature5":
        return FifthDegreeCubatureRule()
    if rule == "central_difference":
        return CentralDifferenceRule(float(h))
    raise ValueError(f"rule must be one of {list(RULES)}, got {rule!r}")


class IEKF(GaussianFilter):
    """Iterated extended Kalman filter (module docstring)."""

    config_name = "iekf"
    Params = IEKFParams

    def __init__(self, model: FilterModel, iterations: int = 10, tolerance: float = 0.0) -> None:
        super().__init__(model, Integration(Taylor(), iterations, tolerance))


class IPLF(GaussianFilter):
    """Iterated posterior-linearisation filter (module docstring)."""

    config_name = "iplf"
    Params = IPLFParams

    def __init__(
        self,
        model: FilterModel,
        rule: str = "cubature",
        p: int = 3,
        alpha: float = 1.0,
        beta: float = 0.0,
        kappa: float = 0.0,
        h: float = 3.0**0.5,
        iterations: int = 10,
        tolerance: float = 0.0,
    ) -> None:
        linearisation = StatisticalLinearRegression(integration_rule(rule, p, alpha, beta, kappa, h))
        linearisation.rule.validate(model.n_err)
        super().__init__(model, Integration(linearisation, iterations, tolerance))
