"""First-order divided-difference filter DD1 (Nørgaard, Poulsen & Ravn 2000, Automatica 36(11)),
square-root form: the worked example of a user-written integration rule in
``docs/plugins.md``. This module and ``conf/estimator/dd1.yaml`` are all it takes.

DD1 keeps only the first-order divided differences of the central-difference rule: the mean is
the function at the centre point (``wm = [1, 0, …]``) and ``S = qr{[(Y_1:n − Y_n+1:2n)/(2h), √noise]}``.
It is the Kalman filter on a linear model, and differs from the CDKF (DD2) by the second-order
terms on a nonlinear one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from quadest.estimators.params import ranged
from quadest.estimators.robust_params import RobustParams, robust_settings
from quadest.estimators.sigma_point import SquareRootSigmaPointFilter
from quadest.models.base import FilterModel
from quadest.numerics.rules import CentralDifferenceRule


@dataclass(frozen=True)
class FirstOrderDividedDifferenceRule(CentralDifferenceRule):
    """Central-difference points with first-order columns only (DD1)."""

    name: str = "divided_difference_1"

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        wm = np.zeros(2 * n + 1)
        wm[0] = 1.0
        return wm, wm

    def sqrt_columns(self, D: np.ndarray, n: int) -> np.ndarray:
        return self._first_order(D, n)

    def posterior_columns(self, DX: np.ndarray, DY: np.ndarray, K: np.ndarray, n: int) -> np.ndarray:
        return self._first_order(DX, n) - K @ self._first_order(DY, n)


@dataclass
class DD1Params(RobustParams):
    """Configuration of ``estimator=dd1``."""

    kind: str = "dd1"
    h: float = ranged(float(np.sqrt(3.0)), "divided-difference step", ge=1.0)
    augmented: bool = False


class DD1(SquareRootSigmaPointFilter):
    """Square-root DD1 filter."""

    config_name = "dd1"
    Params = DD1Params

    def __init__(
        self, model: FilterModel, h: float = float(np.sqrt(3.0)), augmented: bool = False, **robust: Any
    ) -> None:
        super().__init__(model, FirstOrderDividedDifferenceRule(float(h)), augmented, robust_settings(**robust))
