"""One batched Gaussian filter for every :class:`~quadest.estimators.integrations.Integration`.

Särkkä & Svensson (2023), §9–§10: with the transition made affine about the posterior,
``f(x) ≈ f̄ + A (x ⊟ m) + e``, ``e ~ N(0, Λ)``, the prediction is

    m⁻ = f̄,   P⁻ = A P Aᵀ + Λ,   C = Cov(x_k, x_{k+1}) = P Aᵀ;

with a measurement made affine about ``N(m_i, P_i)`` (``m_0 = m⁻``, ``P_0 = P⁻``),
``h(x) ≈ ȳ_i + H_i (x ⊟ m_i) + e``, ``e ~ N(0, Ω_i)``, each iteration conditions the *prior*:

    ν = r(z, ȳ_i) − H_i (m⁻ ⊟ m_i),   S = H_i P⁻ H_iᵀ + Ω_i,   K = P⁻ H_iᵀ S⁻¹,
    m_{i+1} = m⁻ ⊞ K ν,   P_{i+1} = P⁻ − K S Kᵀ,

``r`` the measurement's residual (``z − ẑ`` unless it wraps, :class:`~quadest.models.base.MeasurementModel`).
One iteration is the EKF (Taylor) or the sigma-point filter of the rule (statistical linear
regression); more are the IEKF (Algorithm 7.9 of the book) and the IPLF (Algorithm 10.11). The
innovation reported for the NIS is the first iteration's (against the prior). On a manifold state
the correction is injected with ``⊞`` and no reset Jacobian is applied.

The filter owns, once for every integration: the per-run failure flags (a factorisation that
fails flags its run and lends it the identity), the quarantine of failed runs, the innovation
bookkeeping, the RTS smoother's steps (``G = C (P⁻)⁻¹``, residual ``P − G P⁻ Gᵀ``) and, for the
iterated smoothers, the record of the inputs and measurements it saw
(:meth:`GaussianFilter.iterated_smoothing`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from quadest.estimators.base import Estimator
from quadest.estimators.gaussian_steps import symmetric
from quadest.estimators.integrations import Integration
from quadest.estimators.iterated_smoothing import Step, Update, iterated_smoother
from quadest.estimators.smoothing import SmootherStep, SmoothingForm
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky, kalman_gain, psd_sqrt
from quadest.numerics import matrix_transpose as _t


@dataclass
class _Record:
    """What the iterated smoothers need of the forward pass: the start and every step."""

    x0: np.ndarray
    P0: np.ndarray
    steps: list[Step] = field(default_factory=list)


class GaussianFilter(Estimator):
    """The Gaussian filter of an integration (module docstring), batched over Monte Carlo runs.

    A concrete estimator sets ``config_name`` and ``Params`` and builds its integration."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "smoothing", "iterated_smoothing"})

    def __init__(self, model: FilterModel, integration: Integration) -> None:
        super().__init__(model)
        self.integration = integration
        self._sqrt_R = psd_sqrt(model.R, "R")

    def _factor(self, A: np.ndarray, what: str) -> np.ndarray:
        """Lower factors of ``A`` (B, k, k); a live run where ``A`` is not positive definite is
        flagged and gets the identity."""
        L, bad = batched_cholesky(A)
        if bad.any():
            live = bad & ~self.failed
            if live.any():
                self.flag(np.flatnonzero(live), f"{what} not positive definite")
            L[bad] = np.eye(A.shape[-1])
        return L

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        self.x = np.array(x0, dtype=float, copy=True)
        B = self.x.shape[0]
        self.P = np.array(np.broadcast_to(P0, (B, *np.shape(P0)[-2:])), dtype=float)
        self._reset_failures(B)
        self._x_safe, self._P_safe = self.x.copy(), self.P.copy()
        self._nu = np.zeros((B, self.model.m))
        self._Sy = np.broadcast_to(self._sqrt_R, (B, *self._sqrt_R.shape)).copy()
        self._record = _Record(self.x.copy(), self.P.copy()) if self.smoothing else None

    def predict(self, u: np.ndarray) -> None:
        """``m⁻ = f̄``, ``P⁻ = A P Aᵀ + Λ``; with smoothing on, the RTS step from ``C = P Aᵀ``."""
        affine = self.integration.linearisation.transition(self.model, self.x, self.P, u, self._factor)
        A = affine.jacobian
        P_pred = symmetric(A @ self.P @ _t(A) + affine.noise)
        if self.smoothing:
            G = kalman_gain(self.P @ _t(A), self._factor(P_pred, "predicted covariance"))
            self.smoother_step = SmootherStep(G, affine.mean.copy(), symmetric(self.P - G @ P_pred @ _t(G)))
            self._record.steps.append(Step(np.array(u, dtype=float, copy=True)))
        self.x, self.P = np.array(affine.mean, dtype=float, copy=True), P_pred
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """The iterated update of the module docstring (one iteration: the plain filter)."""
        model, integration = self.model, self.integration
        meas = model.measurement(sensor)
        m_prior, P_prior = self.x, self.P
        m, P = m_prior.copy(), P_prior.copy()
        active = ~self.failed
        for i in range(integration.iterations):
            affine = integration.linearisation.measurement(model, sensor, m, P, u, self._factor)
            H = affine.jacobian
            nu = meas.innovation(z, affine.mean) - (H @ model.boxminus(m_prior, m)[..., None])[..., 0]
            S = symmetric(H @ P_prior @ _t(H) + affine.noise)
            Sy = self._factor(S, "innovation covariance")
            K = kalman_gain(P_prior @ _t(H), Sy)
            m_next = model.boxplus(m_prior, (K @ nu[..., None])[..., 0])
            P_next = symmetric(P_prior - K @ S @ _t(K))
            if i == 0:
                self._nu, self._Sy = nu, Sy
            moved = np.max(np.abs(model.boxminus(m_next, m)), axis=-1)
            m[active], P[active] = m_next[active], P_next[active]
            active = active & (moved > integration.tolerance)
            if not active.any():
                break
        self.x, self.P = m, P
        if self._record is not None and self._record.steps:
            self._record.steps[-1].updates.append(Update(sensor, np.array(z, dtype=float, copy=True), u.copy()))
        self.quarantine(self.x, self.P, self._x_safe, self._P_safe)

    def smoothing_form(self) -> SmoothingForm:
        """Covariance form; the model's ⊞/⊟ on a manifold state (no reset Jacobian)."""
        if not self.model.has_manifold_state:
            return SmoothingForm()
        return SmoothingForm(boxplus=self.model.boxplus, boxminus=self.model.boxminus)

    def iterated_smoothing(
        self, iterations: int, filtered_means: np.ndarray, filtered_covariances: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The iterated smoother of this filter's integration over the run just filtered (IERTS for
        Taylor, IPLS for statistical linear regression; :mod:`quadest.estimators.iterated_smoothing`),
        started from the filtered means and covariances (K+1, B, ·) of steps 0..K."""
        if self._record is None:
            raise RuntimeError("iterated smoothing needs smoothing switched on before initialize")
        return iterated_smoother(
            self.model,
            self.integration.linearisation,
            self._record.x0,
            self._record.P0,
            self._record.steps,
            filtered_means,
            filtered_covariances,
            iterations,
        )

    @property
    def mean(self) -> np.ndarray:
        return self.x

    @property
    def covariance(self) -> np.ndarray:
        return self.P

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self._nu, self._Sy
