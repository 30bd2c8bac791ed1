"""Gauss–Hermite Kalman filter (Ito & Xiong 2000, IEEE TAC 45(5)), covariance form, batched:
the sigma-point filter with a tensor-product Gauss–Hermite rule of ``p`` points per dimension
(p^n points; exact for polynomials of degree ≤ 2p − 1 in each coordinate)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from quadest.estimators.params import ranged
from quadest.estimators.robust_params import RobustParams, robust_settings
from quadest.estimators.sigma_point import SigmaPointKalmanFilter
from quadest.models.base import FilterModel
from quadest.numerics.rules import GaussHermiteRule


@dataclass
class GaussHermiteParams(RobustParams):
    """Configuration of ``estimator=ghkf``: points per dimension (3 is fifth-degree exact)."""

    kind: str = "ghkf"
    p: int = ranged(3, "points per dimension (p^n points in all)", ge=1, integer=True)
    augmented: bool = False

    @staticmethod
    def constraints(values: Mapping[str, Any], n: int) -> list[tuple[str, Any, str]]:
        """A grid of at most the rule's maximum number of points in the model's dimension ``n``
        (checked before any work; an augmented filter's larger dimension is checked when it is built)."""
        why = GaussHermiteRule(int(values.get("p", 3))).size_problem(n) if n > 0 else None
        return [] if why is None else [("p", values.get("p", 3), f"{why} or use estimator=ckf")]


class GHKF(SigmaPointKalmanFilter):
    """Gauss–Hermite Kalman filter, covariance form."""

    config_name = "ghkf"
    Params = GaussHermiteParams

    def __init__(self, model: FilterModel, p: int = 3, augmented: bool = False, **robust: Any) -> None:
        super().__init__(model, GaussHermiteRule(p), augmented, robust_settings(**robust))
