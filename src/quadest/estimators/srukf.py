"""Square-root unscented Kalman filter of the thesis (seed 000, chapter 5, eqs 5.12–5.29),
batched over Monte Carlo runs: the square-root sigma-point filter with the unscented rule.

State per run: the mean ``x`` (n,) and a lower-triangular factor ``S`` (n, n) with ``P = S Sᵀ``.
The whole batch advances in one call per step: sigma points (B, 2n+1, n) go through the model's
``f`` and ``h`` at once; ``qr`` and ``cholupdate`` are batched (:mod:`quadest.numerics`). The
W0 downdate (eqs 5.19, 5.24) is the unscented rule's (:class:`~quadest.numerics.rules.UnscentedRule`).
``robust: true`` replaces the Kalman update by the Huber M-estimation update (Karlgaard & Schaub
2007; :mod:`quadest.numerics.huber`).

On the compiled backend (``QUADEST_KERNELS=numba``) the plain SR-UKF (not augmented, not robust,
the primary measurement with the residual ``z − ẑ``) of a model that declares ``fused_unscented``
(compiled ``f``/``h`` for sigma points, like the thesis quadrotor) and a vector state takes each
step in three fused calls per stage (:mod:`quadest.numerics.unscented`: points, moments,
correction) around the model's ``f`` and ``h``. Every other case, and the ``numpy`` backend, takes
the sigma-point family's path (:class:`~quadest.estimators.sigma_point.SquareRootSigmaPointFilter`),
bit for bit; the fused path
agrees with it to round-off (tests/test_srukf_identities.py), as the compiled ``f``/``h`` agree
with their numpy references.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.estimators.params import ranged, unscented_constraints
from quadest.estimators.robust_params import DEFAULT, HuberParams, robust_settings
from quadest.estimators.sigma_point import SquareRootSigmaPointFilter
from quadest.models.base import FilterModel
from quadest.numerics.rules import UnscentedRule
from quadest.numerics.square_root import DOWNDATE_FAILED, kernel_backend
from quadest.numerics.unscented import unscented_correction, unscented_moments, unscented_points


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

    def _fused(self) -> bool:
        """Whether this step takes the fused path (see the module docstring)."""
        return (
            not self.augmented
            and self.huber is None
            and self.model.fused_unscented
            and not self.model.has_manifold_state
            and kernel_backend() == "numba"
        )

    def predict(self, u: np.ndarray) -> None:
        """Time update (eqs 5.15–5.19), fused on the compiled backend."""
        if not self._fused():
            super().predict(u)
            return
        ut = self.rule.ut(self.model.n)
        points, x_prior = unscented_points(self.x, self.S, ut.gamma), self.x  # (5.15)
        X = self.model.f(points, u)  # (5.16)
        self.x, self.S, failed = unscented_moments(X, ut, self.sqrt_Q)  # (5.17)–(5.19)
        self._flag_downdates(failed)
        if self.smoothing:
            self._record_smoother_step(points - x_prior[:, None, :], X - self.x[:, None, :], self.model.n, self.sqrt_Q)
        self.quarantine(self.x, self.S, self._x_safe, self._spread_safe)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """Measurement update (eqs 5.20–5.29), fused on the compiled backend for the primary
        measurement when its residual is ``z − ẑ`` (the kernel's); a measurement with its own
        residual takes the sigma-point family's path."""
        if sensor is not None or not self._fused() or self.model.measurement().residual is not None:
            super().update(z, u, sensor)
            return
        ut = self.rule.ut(self.model.n)
        X = unscented_points(self.x, self.S, ut.gamma)  # (5.20)
        Y = self.model.h(X, u)  # (5.21)
        y_mean, Sy, failed_y = unscented_moments(Y, ut, self.sqrt_R)  # (5.22)–(5.24)
        self._flag_downdates(failed_y)
        self.x, self.S, self._nu, failed = unscented_correction(X, self.x, Y, y_mean, ut.wc, Sy, self.S, z)
        self._Sy = Sy  # (5.25)–(5.29)
        self._flag_downdates(failed)
        self.quarantine(self.x, self.S, self._x_safe, self._spread_safe)

    def _flag_downdates(self, failed: np.ndarray) -> None:
        if failed.any():
            self.flag(np.flatnonzero(failed), DOWNDATE_FAILED)
