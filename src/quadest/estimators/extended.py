"""Huber-based extended Kalman filter (``hf``; Karlgaard & Schaub 2007, seed 004's HF), batched.

The EKF of filterpy's equations, for the whole batch at once: ``x⁻ = f(x, u)``,
``P⁻ = F P Fᵀ + Q`` with ``F`` the Jacobian at the posterior mean; ``H`` at the prior mean,
``Pyy = H P⁻ Hᵀ + R``, ``K = P⁻ Hᵀ Pyy⁻¹`` and the Joseph form
``P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ``. The measurement update is the Huber update of the
sigma-point family (:func:`~quadest.numerics.huber.huber_update` with ``Pxy = P⁻ Hᵀ``, for which
``R̄ = R``): a run whose whitened residuals at the Kalman solution all lie within γ keeps the
EKF's update, so as γ → ∞ ``hf`` is filterpy's EKF (``ekf``) up to round-off. On a model with a
manifold state (``model=ins``) the same equations run on the error state (``F_err``, ``H_err``,
``x ← x ⊞ δx̂``): the error-state EKF of ``mekf`` without the reset Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.estimators.error_state_ekf import BatchedEKFBase
from quadest.estimators.gaussian_steps import joseph_covariance, kalman_correction
from quadest.estimators.robust_params import DEFAULT, HuberParams, huber_settings
from quadest.models.base import FilterModel
from quadest.numerics import matrix_transpose as _t
from quadest.numerics.huber import HuberCounts


@dataclass
class HuberEKFParams(HuberParams):
    """Configuration of ``estimator=hf``: the Huber settings."""

    kind: str = "hf"


class HuberEKF(BatchedEKFBase):
    """Batched Huber EKF (module docstring)."""

    config_name = "hf"
    Params = HuberEKFParams

    def __init__(
        self,
        model: FilterModel,
        huber_threshold: float = DEFAULT.threshold,
        huber_max_iterations: int = DEFAULT.max_iterations,
        huber_tolerance: float = DEFAULT.tolerance,
    ) -> None:
        super().__init__(model)
        self.huber = huber_settings(huber_threshold, huber_max_iterations, huber_tolerance)

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        B = np.shape(x0)[0]
        P = np.array(np.broadcast_to(P0, (B, *np.shape(P0)[-2:])), dtype=float)
        self._start(x0, P, np.linalg.cholesky(self.model.R))
        self._counts = HuberCounts(B)

    def predict(self, u: np.ndarray) -> None:
        self._linearized_predict(u)
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        H, R, moments = self._linearized_measurement(z, u, sensor)
        # Pyy factored as computed (Cholesky reads its lower triangle), not symmetrised as mekf's
        # is: these are the digits the checked-in Huber results were made with
        self._Sy = self._cholesky(moments.cov, "innovation covariance")
        conditioned = kalman_correction(
            self._nu, moments.cross, self._Sy, self.huber, self._cholesky(self.P, "covariance")
        )
        step = conditioned.huber
        self.x = self.model.boxplus(self.x, step.correction)
        self.P = joseph_covariance(self.P, H, R, conditioned.gain)
        self.P[step.robust] = step.factor[step.robust] @ _t(step.factor[step.robust])
        self._counts.add(step, self._nu.shape[-1])
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)

    def diagnostics(self) -> dict[str, np.ndarray]:
        """The IRLS counts per run (:class:`~quadest.numerics.huber.HuberCounts`)."""
        return self._counts.diagnostics()
