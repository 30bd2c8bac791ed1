"""Huber-based cubature filters of seed 004 and the Huber settings every robust filter takes.

- ``hckf``: third-degree cubature Kalman filter (Arasaratnam & Haykin 2009) with the Huber
  measurement update (Karlgaard & Schaub 2007): seed 004's HCKF;
- ``hhcf``: fifth-degree ("high-degree") cubature filter (Jia, Xin & Cheng 2013) with the Huber
  update: seed 004's robust high-degree cubature filter (HHCF).

Both are the covariance-form sigma-point filter with its rule and ``huber`` settings; the update
itself is :meth:`~quadest.estimators.sigma_point.SigmaPointFilter._measurement_update`, shared by
every filter of the family (``robust: true`` on ``srukf``) and by the Huber EKF (``hf``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from quadest.estimators.params import ranged
from quadest.estimators.sigma_point import SigmaPointKalmanFilter
from quadest.models.base import FilterModel
from quadest.numerics.huber import HuberSettings
from quadest.numerics.rules import CubatureRule, FifthDegreeCubatureRule, IntegrationRule

DEFAULT = HuberSettings()


@dataclass
class HuberParams:
    """The Huber update's settings (:class:`~quadest.numerics.huber.HuberSettings`)."""

    huber_threshold: float = ranged(DEFAULT.threshold, "Huber threshold gamma; 1.345: 95 % Gaussian efficiency", gt=0.0)
    huber_max_iterations: int = ranged(DEFAULT.max_iterations, "IRLS iteration limit", ge=1, integer=True)
    huber_tolerance: float = ranged(DEFAULT.tolerance, "IRLS stop: correction step in prior sigmas", gt=0.0)


def huber_settings(threshold: float, max_iterations: int, tolerance: float) -> HuberSettings:
    """Settings from the config keys of :class:`HuberParams`."""
    return HuberSettings(float(threshold), int(max_iterations), float(tolerance))


@dataclass
class RobustParams(HuberParams):
    """``robust: true`` replaces a sigma-point filter's Kalman update by the Huber one (Karlgaard &
    Schaub 2007), with the ``huber_*`` settings; any filter of the family takes these keys."""

    robust: bool = False


def robust_settings(
    robust: bool = False,
    huber_threshold: float = DEFAULT.threshold,
    huber_max_iterations: int = DEFAULT.max_iterations,
    huber_tolerance: float = DEFAULT.tolerance,
) -> HuberSettings | None:
    """The Huber settings of the :class:`RobustParams` keys, ``None`` for the Kalman update."""
    return huber_settings(huber_threshold, huber_max_iterations, huber_tolerance) if robust else None


@dataclass
class HuberCubatureParams(HuberParams):
    """Configuration of ``estimator=hckf``/``hhcf``."""

    kind: str = "hckf"
    augmented: bool = False


class _HuberCubatureFilter(SigmaPointKalmanFilter):
    """The covariance-form sigma-point filter with the Huber update; a subclass names its cubature rule."""

    Params = HuberCubatureParams
    Rule: ClassVar[type[IntegrationRule]]

    def __init__(
        self,
        model: FilterModel,
        huber_threshold: float = DEFAULT.threshold,
        huber_max_iterations: int = DEFAULT.max_iterations,
        huber_tolerance: float = DEFAULT.tolerance,
        augmented: bool = False,
    ) -> None:
        huber = huber_settings(huber_threshold, huber_max_iterations, huber_tolerance)
        super().__init__(model, self.Rule(), augmented, huber)


class HCKF(_HuberCubatureFilter):
    """Huber third-degree cubature Kalman filter (seed 004's HCKF), covariance form."""

    config_name = "hckf"
    Rule = CubatureRule


class HHCF(_HuberCubatureFilter):
    """Huber fifth-degree cubature filter (seed 004's HHCF), covariance form: 2n² + 1 points,
    negative axis weights for n > 4 (a run that loses definiteness is flagged, as in ``ckf5``)."""

    config_name = "hhcf"
    Rule = FifthDegreeCubatureRule
