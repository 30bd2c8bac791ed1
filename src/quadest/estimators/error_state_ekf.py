"""The multiplicative (error-state) extended Kalman filter, batched over Monte Carlo runs.

Markley 2003 ("Attitude error representations for Kalman filtering", JGCD 26(2)); Solà 2017
("Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508, §5–§7). The filter
keeps the nominal state ``x`` (B, n) on the model's manifold and the covariance ``P``
(B, n_err, n_err) of the error ``δx`` with ``x_true = x ⊞ δx``:

- predict: ``x ← f(x, u)``, ``P ← F P Fᵀ + Q`` with ``F = model.F_err`` (Solà eqs. 268–270);
- update with the primary measurement or a named sensor: ``H = model.H_err``,
  ``S = H P Hᵀ + R``, ``K = P Hᵀ S⁻¹`` (two triangular solves), ``δx̂ = K ν``,
  ``P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ`` (Joseph form; Solà eqs. 274–276);
- reset after every update: the correction is injected, ``x ← x ⊞ δx̂``, the error mean returns
  to zero and, with ``reset_jacobian: true`` (default), ``P ← G P Gᵀ`` with
  ``G = model.reset_jacobian(x, δx̂)`` (Solà eqs. 284–287; for the attitude
  ``G_θ = J_r(δθ̂) ≈ I − [δθ̂/2]×``). Markley 2003 drops this term (``G = I``), which is
  second order in the correction; ``reset_jacobian: false`` gives that filter.

The linearised steps are the shared Gaussian steps (:mod:`quadest.estimators.gaussian_steps`).
Everything goes through the model (``f``, ``boxplus``, ``F_err``, ``H_err``, ``Q``,
``measurement(sensor)``), so any model with ``n_err``/``boxplus``/``boxminus`` runs unchanged; on
vector-state models ``F_err = F``, ``H_err = H``, ``G = I`` and the filter is the EKF (on a
linear-Gaussian model, the Kalman filter).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from quadest.estimators.base import Estimator
from quadest.estimators.gaussian_steps import (
    MeasurementMoments,
    joseph_covariance,
    kalman_correction,
    linearized_covariance,
    linearized_moments,
    symmetric,
)
from quadest.estimators.smoothing import SmoothingForm, linearized_smoother_step
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky, psd_sqrt
from quadest.numerics import matrix_transpose as _t


@dataclass
class MEKFParams:
    """Configuration of ``estimator=mekf``: whether the covariance reset Jacobian is applied."""

    kind: str = "mekf"
    reset_jacobian: bool = True


class BatchedEKFBase(Estimator):
    """What the batched linearized filters (``mekf`` here, ``hf`` in
    :mod:`~quadest.estimators.extended`) share: the nominal state ``x`` (B, n), the error covariance
    ``P`` (B, n_err, n_err), the last innovation and the lower factor of its covariance, the
    quarantine copies, a Cholesky factor that flags the runs where it fails, and the linearised
    steps (:mod:`~quadest.estimators.gaussian_steps`): the time update and a measurement's
    moments."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "smoothing"})
    reset_covariance: bool = False

    def _start(self, x0: np.ndarray, P0: np.ndarray, sqrt_R: np.ndarray) -> None:
        """Start every run at ``x0`` (B, n) with covariance ``P0`` (B, n_err, n_err, owned by the
        filter) and the innovation factor ``sqrt_R`` (m, m) until the first update."""
        self.x = np.array(x0, dtype=float, copy=True)
        self.P = P0
        B = self.x.shape[0]
        self._reset_failures(B)
        self._x_safe, self._P_safe = self.x.copy(), self.P.copy()
        self._nu = np.zeros((B, self.model.m))
        self._Sy = np.broadcast_to(sqrt_R, (B, *sqrt_R.shape)).copy()

    def _cholesky(self, A: np.ndarray, what: str) -> np.ndarray:
        """Lower factors of ``A`` (B, k, k); a run where ``A`` is not positive definite is flagged
        and gets the identity."""
        L, bad = batched_cholesky(A)
        if bad.any():
            self.flag(np.flatnonzero(bad), f"{what} not positive definite")
            L[bad] = np.eye(A.shape[-1])
        return L

    def _linearized_predict(self, u: np.ndarray) -> None:
        """``x ← f(x, u)``, ``P ← F P Fᵀ + Q`` with ``F = model.F_err`` at the posterior mean; with
        smoothing on, also the RTS smoother's step (:func:`~quadest.estimators.smoothing.linearized_smoother_step`)."""
        F = self.model.F_err(self.x, u)
        P_prior = self.P
        self.x = self.model.f(self.x[:, None, :], u)[:, 0]
        self.P = linearized_covariance(F, P_prior, self.model.Q)
        if self.smoothing:
            factor = self._cholesky(symmetric(self.P), "predicted covariance")
            self.smoother_step = linearized_smoother_step(P_prior, F, self.model.Q, factor, self.x.copy())

    def smoothing_form(self) -> SmoothingForm:
        """Covariance form; on a manifold state the model's ⊞/⊟, and its reset Jacobian when this
        filter resets its covariance."""
        if not self.model.has_manifold_state:
            return SmoothingForm()
        reset = self.model.reset_jacobian if self.reset_covariance else None
        return SmoothingForm(boxplus=self.model.boxplus, boxminus=self.model.boxminus, reset_jacobian=reset)

    def _linearized_measurement(
        self, z: np.ndarray, u: np.ndarray, sensor: str | None
    ) -> tuple[np.ndarray, np.ndarray, MeasurementMoments]:
        """``H = model.H_err`` at the prior mean and the measurement's moments; stores the
        innovation, the measurement's residual ``r(z, h(x̂⁻))``. Returns ``(H, R, moments)``."""
        meas = self.model.measurement(sensor)
        H = self.model.H_err(self.x, u, sensor)
        moments = linearized_moments(meas.h(self.x[:, None, :], u)[:, 0], H, self.P, meas.R)
        self._nu = meas.innovation(z, moments.mean)
        return H, meas.R, moments

    @property
    def mean(self) -> np.ndarray:
        return self.x

    @property
    def covariance(self) -> np.ndarray:
        return self.P

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self._nu, self._Sy


class ErrorStateEKF(BatchedEKFBase):
    """Multiplicative / error-state EKF on any :class:`FilterModel` (see the module docstring)."""

    config_name: ClassVar[str] = "mekf"
    Params: ClassVar[type] = MEKFParams

    def __init__(self, model: FilterModel, reset_jacobian: bool = True) -> None:
        super().__init__(model)
        if not isinstance(reset_jacobian, bool | np.bool_):
            raise ValueError(f"reset_jacobian must be true or false, got {reset_jacobian!r}")
        self.reset_jacobian = bool(reset_jacobian)
        self.reset_covariance = self.reset_jacobian
        self._sqrt_R = psd_sqrt(model.R, "R")

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self._start(x0, np.array(P0, dtype=float, copy=True), self._sqrt_R)

    def predict(self, u: np.ndarray) -> None:
        self._linearized_predict(u)
        self.P = symmetric(self.P)
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        H, R, moments = self._linearized_measurement(z, u, sensor)
        self._Sy = self._cholesky(symmetric(moments.cov), "innovation covariance")
        conditioned = kalman_correction(self._nu, moments.cross, self._Sy)
        K, dx = conditioned.gain, conditioned.correction
        P = joseph_covariance(self.P, H, R, K)
        x_prior = self.x
        self.x = self.model.boxplus(x_prior, dx)
        if self.reset_jacobian:
            G = self.model.reset_jacobian(x_prior, dx)
            P = G @ P @ _t(G)
        self.P = symmetric(P)
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)
