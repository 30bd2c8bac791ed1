"""The cubature filters of seed 004 under the seed's names, and the Huber third-degree filter.

Seed 004 (Chen, Wang, Qin, Cui & Xu 2017, §1 and §4.2) compares EKF, HF, HCKF and HHCF:

- ``hckf``: the seed's HCKF, "高阶容积卡尔曼滤波", the plain (L2) fifth-degree ("high-degree")
  cubature Kalman filter of Jia, Xin & Cheng 2013 (the seed's ref. [6]): ``ckf5`` under the seed's
  name, without a Huber update (the seed calls it non-robust);
- ``hhcf``: the seed's HHCF, the same filter with the Huber measurement update (Karlgaard &
  Schaub 2007): ``ckf5`` with ``robust: true``;
- ``huber_ckf``: the third-degree cubature filter (Arasaratnam & Haykin 2009) with the Huber
  update, ``ckf`` with ``robust: true`` (not one of the seed's filters).

The Huber update is :meth:`~quadest.estimators.sigma_point.SigmaPointFilter._measurement_update`,
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
    """Configuration of ``estimator=huber_ckf``/``hhcf`` (always robust: no ``robust`` key)."""

    kind: str = "huber_ckf"
    augmented: bool = False


@dataclass
class HighDegreeCubatureParams:
    """Configuration of ``estimator=hckf`` (never robust: no ``robust`` or ``huber_*`` keys)."""

    kind: str = "hckf"
    augmented: bool = False


class HCKF(CKF5):
    """Seed 004's HCKF: the plain fifth-degree cubature Kalman filter, covariance form; ``ckf5``
    under the seed's name (2n² + 1 points, negative axis weights for n > 4: a run that loses
    definiteness is flagged, as in ``ckf5``)."""

    config_name = "hckf"
    Params = HighDegreeCubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False) -> None:
        super().__init__(model, augmented)


class HuberCKF(CKF):
    """Huber third-degree cubature Kalman filter, covariance form: ``ckf`` with ``robust: true``."""

    config_name = "huber_ckf"
    Params = HuberCubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **huber: Any) -> None:
        super().__init__(model, augmented, robust=True, **huber)


class HHCF(CKF5):
    """Seed 004's HHCF: the Huber fifth-degree cubature filter, covariance form: ``ckf5`` with
    ``robust: true`` (2n² + 1 points, negative axis weights for n > 4: a run that loses
    definiteness is flagged, as in ``ckf5``)."""

    config_name = "hhcf"
    Params = HuberCubatureParams

    def __init__(self, model: FilterModel, augmented: bool = False, **huber: Any) -> None:
        super().__init__(model, augmented, robust=True, **huber)
