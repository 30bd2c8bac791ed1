"""Huber-based cubature filters of seed 004.

- ``hckf``: third-degree cubature Kalman filter (Arasaratnam & Haykin 2009) with the Huber
  measurement update (Karlgaard & Schaub 2007): seed 004's HCKF;
- ``hhcf``: fifth-degree ("high-degree") cubature filter (Jia, Xin & Cheng 2013) with the Huber
  update: seed 004's robust high-degree cubature filter (HHCF).

Both are ``ckf``/``ckf5`` with ``robust: true`` (:class:`~quadest.estimators.robust_params.RobustParams`);
the update itself is :meth:`~quadest.estimators.sigma_point.SigmaPointFilter._measurement_update`,
shared by every filter of the family and by the Huber EKF (``hf``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from quadest.estimators.cubature import CKF, CKF5
from quadest.estimators.robust_params import HuberParams
from quadest.models.base import FilterModel


@dataclass
class HuberCubatureParams(HuberParams):
    """Configuration of ``estimator=hckf``/``hhcf`` (always robust: no ``robust`` key)."""

    kind: str = "hckf"
    augmented: bool = False


class HCKF(CKF):
    """Huber third-degree cubature Kalman filter (seed 004's HCKF), covariance form: ``ckf`` with
    ``robust: true``."""

    config_name = "hckf"
    Params = HuberCubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **huber: Any) -> None:
        super().__init__(model, augmented, robust=True, **huber)


class HHCF(CKF5):
    """Huber fifth-degree cubature filter (seed 004's HHCF), covariance form: ``ckf5`` with
    ``robust: true`` (2n² + 1 points, negative axis weights for n > 4: a run that loses
    definiteness is flagged, as in ``ckf5``)."""

    config_name = "hhcf"
    Params = HuberCubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **huber: Any) -> None:
        super().__init__(model, augmented, robust=True, **huber)
