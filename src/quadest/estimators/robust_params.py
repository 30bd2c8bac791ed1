"""The configuration keys of the Huber update (Karlgaard & Schaub 2007) every robust filter takes:
``huber_*`` settings (:class:`HuberParams`) and, for the sigma-point family, the ``robust``
switch (:class:`RobustParams`); the update itself is :mod:`quadest.numerics.huber`."""

from __future__ import annotations

from dataclasses import dataclass

from quadest.estimators.params import ranged
from quadest.numerics.huber import HuberSettings

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
