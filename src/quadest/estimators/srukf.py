"""Square-root unscented Kalman filter of the thesis (seed 000, chapter 5, eqs 5.12–5.29),
batched over Monte Carlo runs: the square-root sigma-point filter with the unscented rule.

State per run: the mean ``x`` (n,) and a lower-triangular factor ``S`` (n, n) with ``P = S Sᵀ``.
The whole batch advances in one call per step: sigma points (B, 2n+1, n) go through the model's
``f`` and ``h`` at once; ``qr`` and ``cholupdate`` are batched (:mod:`quadest.numerics`). The
W0 downdate (eqs 5.19, 5.24) is the unscented rule's (:class:`~quadest.numerics.rules.UnscentedRule`).
``robust: true`` replaces the Kalman update by the Huber M-estimation update (Karlgaard & Schaub
2007; :mod:`quadest.numerics.huber`).
"""

from __future__ import annotations

from dataclasses import dataclass

from quadest.estimators.params import ranged, unscented_constraints
from quadest.estimators.robust_params import DEFAULT, HuberParams, robust_settings
from quadest.estimators.sigma_point import SquareRootSigmaPointFilter
from quadest.models.base import FilterModel
from quadest.numerics.rules import UnscentedRule


@dataclass
class SRUKFParams(HuberParams):
    """Configuration of ``estimator=srukf``: the UT scaling parameters (eqs 5.2–5.6) and the
    Huber update (``robust``, with the ``huber_*`` settings)."""

    kind: str = "srukf"
    alpha: float = ranged(0.5, "spread of the sigma points; typically 1e-4 <= alpha <= 1", gt=0.0)
    beta: float = ranged(2.0, "prior knowledge of the distribution; 2 is optimal for a Gaussian")
    kappa: float = ranged(0.0, "secondary scaling; usually 0 for state estimation")
    augmented: bool = False
    robust: bool = False

    constraints = staticmethod(unscented_constraints)


class SRUKF(SquareRootSigmaPointFilter):
    """Batched SR-UKF, thesis eqs 5.12–5.29.

    Args:
        model: the filter model, bound to a batch of B runs.
        alpha, beta, kappa: UT parameters. ``W0(c)`` may be negative (small α); eqs 5.19 and
            5.24 then become Cholesky downdates, and a downdate that would make a covariance
            indefinite flags its run as failed (:class:`~quadest.errors.DowndateError`).
        augmented: noise in the sigma-point state (dimension n + q + r), points drawn once per step.
        robust: the Huber measurement update with threshold ``huber_threshold``, at most
            ``huber_max_iterations`` IRLS iterations, stopping at ``huber_tolerance``.
    """

    config_name = "srukf"
    Params = SRUKFParams

    def __init__(
        self,
        model: FilterModel,
        alpha: float = 0.5,
        beta: float = 2.0,
        kappa: float = 0.0,
        augmented: bool = False,
        robust: bool = False,
        huber_threshold: float = DEFAULT.threshold,
        huber_max_iterations: int = DEFAULT.max_iterations,
        huber_tolerance: float = DEFAULT.tolerance,
    ) -> None:
        huber = robust_settings(robust, huber_threshold, huber_max_iterations, huber_tolerance)
        super().__init__(model, UnscentedRule(float(alpha), float(beta), float(kappa)), augmented, huber)
