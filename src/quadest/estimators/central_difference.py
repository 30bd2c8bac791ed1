"""Central-difference Kalman filters, covariance (CDKF) and square-root (SR-CDKF) forms, batched.

Nørgaard, Poulsen & Ravn 2000 (Automatica 36(11)); van der Merwe 2004 (OHSU thesis, the CDKF and
SR-CDKF). Points ``x̂, x̂ ± h S_i``; the covariance comes from divided differences
(:class:`~quadest.numerics.rules.CentralDifferenceRule`), so the square-root form never downdates:
its posterior factor is ``qr{[S⁻ − K Y1, K Y2, K √R]}``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from quadest.estimators.params import ranged
from quadest.estimators.robust_params import RobustParams, robust_settings
from quadest.estimators.sigma_point import SigmaPointKalmanFilter, SquareRootSigmaPointFilter
from quadest.models.base import FilterModel
from quadest.numerics.rules import CentralDifferenceRule

SQRT3 = float(np.sqrt(3.0))


@dataclass
class CentralDifferenceParams(RobustParams):
    """Configuration of ``estimator=cdkf``/``srcdkf``: the step ``h`` (h² = 3 is optimal for a
    Gaussian prior, Nørgaard et al. 2000)."""

    kind: str = "cdkf"
    h: float = ranged(SQRT3, "central-difference step; h^2 = 3 is optimal for a Gaussian", ge=1.0)
    augmented: bool = False


class CDKF(SigmaPointKalmanFilter):
    """Central-difference Kalman filter, covariance form."""

    config_name = "cdkf"
    Params = CentralDifferenceParams

    def __init__(self, model: FilterModel, h: float = SQRT3, augmented: bool = False, **robust: Any) -> None:
        super().__init__(model, CentralDifferenceRule(float(h)), augmented, robust_settings(**robust))


class SRCDKF(SquareRootSigmaPointFilter):
    """Square-root central-difference Kalman filter (van der Merwe 2004)."""

    config_name = "srcdkf"
    Params = CentralDifferenceParams

    def __init__(self, model: FilterModel, h: float = SQRT3, augmented: bool = False, **robust: Any) -> None:
        super().__init__(model, CentralDifferenceRule(float(h)), augmented, robust_settings(**robust))
