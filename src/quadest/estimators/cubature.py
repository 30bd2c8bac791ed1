"""Cubature Kalman filters, covariance and square-root forms, batched over Monte Carlo runs.

- ``ckf``/``srckf``: third-degree spherical–radial rule (Arasaratnam & Haykin 2009, IEEE TAC
  54(6)); the CKF equals the UKF with α = 1, β = 0, κ = 0.
- ``ckf5``/``srckf5``: fifth-degree rule with 2n² + 1 points (Jia, Xin & Cheng 2013, Automatica
  49(2)), the "high-degree" CKF of seed 004. Its axis weights are negative for n > 4: the
  square-root form downdates, the covariance form flags a run that loses definiteness.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from quadest.estimators.robust_params import RobustParams, robust_settings
from quadest.estimators.sigma_point import SigmaPointKalmanFilter, SquareRootSigmaPointFilter
from quadest.models.base import FilterModel
from quadest.numerics.rules import CubatureRule, FifthDegreeCubatureRule


@dataclass
class CubatureParams(RobustParams):
    """Configuration of ``estimator=ckf``/``srckf`` (the third-degree rule has no parameters; the
    ``robust`` and ``huber_*`` keys of :class:`~quadest.estimators.robust_params.RobustParams`)."""

    kind: str = "ckf"
    augmented: bool = False


@dataclass
class FifthDegreeCubatureParams(RobustParams):
    """Configuration of ``estimator=ckf5``/``srckf5`` (the fifth-degree rule has no parameters; the
    ``robust`` and ``huber_*`` keys of :class:`~quadest.estimators.robust_params.RobustParams`)."""

    kind: str = "ckf5"
    augmented: bool = False


class CKF(SigmaPointKalmanFilter):
    """Third-degree cubature Kalman filter, covariance form."""

    config_name = "ckf"
    Params = CubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **robust: Any) -> None:
        super().__init__(model, CubatureRule(), augmented, robust_settings(**robust))


class SRCKF(SquareRootSigmaPointFilter):
    """Third-degree cubature Kalman filter, square-root form (Arasaratnam & Haykin 2009, §VI)."""

    config_name = "srckf"
    Params = CubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **robust: Any) -> None:
        super().__init__(model, CubatureRule(), augmented, robust_settings(**robust))


class CKF5(SigmaPointKalmanFilter):
    """Fifth-degree cubature Kalman filter, covariance form."""

    config_name = "ckf5"
    Params = FifthDegreeCubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **robust: Any) -> None:
        super().__init__(model, FifthDegreeCubatureRule(), augmented, robust_settings(**robust))


class SRCKF5(SquareRootSigmaPointFilter):
    """Fifth-degree cubature Kalman filter, square-root form (multi-column downdates for n > 4)."""

    config_name = "srckf5"
    Params = FifthDegreeCubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **robust: Any) -> None:
        super().__init__(model, FifthDegreeCubatureRule(), augmented, robust_settings(**robust))
