"""Unscented particle filter (``estimator=upf``): one UKF step per particle as the proposal.

van der Merwe, Doucet, de Freitas & Wan (2000), "The unscented particle filter", Algorithm 1 with
the UKF as the proposal generator: every particle keeps its own covariance ``P_i``; one UKF step
from ``(x_i, P_i)`` with ``y_k`` gives ``(μ_i, P̂_i)``; the particle is drawn from ``N(μ_i, P̂_i)``
and weighted like the EKPF's (:mod:`quadest.estimators.particle_ekpf`, whose sampling, weights
and carried ``P_i`` this filter shares; only the proposal moments differ).

With ``augmented: true`` (the paper's choice; van der Merwe 2004) the proposal's noise
joins the sigma-point state ``[x; v; n]`` with covariance ``diag(P_i, Q_p, R_p)`` and goes through
the model's ``f_noise`` and ``h_noise``; otherwise ``Q_p`` and ``R_p`` are added to the
transformed covariances. The points and weights are the sigma-point family's
:class:`~quadest.numerics.rules.UnscentedRule`, for all particles of all runs in one model call,
and the step is the family's Gaussian predict and update (:mod:`~quadest.estimators.gaussian_steps`:
points, weighted means, moments, gain by triangular solves, ``P − K Pyy Kᵀ``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.errors import ConfigError
from quadest.estimators.gaussian_steps import (
    covariance_posterior,
    kalman_correction,
    point_mean,
    sigma_point_covariance,
    sigma_point_moments,
    sigma_points,
)
from quadest.estimators.params import ranged
from quadest.estimators.particle_ekpf import EKPF, EKPFParams
from quadest.models.base import FilterModel
from quadest.numerics.rules import UnscentedRule


@dataclass
class UPFParams(EKPFParams):
    """Configuration of ``estimator=upf``: the EKPF's options plus the UT's and ``augmented``."""

    kind: str = "upf"
    alpha: float = ranged(1.0, "spread of the sigma points", gt=0.0)
    beta: float = ranged(0.0, "prior knowledge of the distribution; 2 is optimal for a Gaussian")
    kappa: float = ranged(2.0, "secondary scaling; n + kappa > 0 for the sigma-point dimension")
    augmented: bool = True


def _flat(X: np.ndarray) -> np.ndarray:
    """The points (B, N, L, d) of every particle as one batch of points per run (B, N·L, d), the
    shape the model's functions take."""
    B, N, L, d = X.shape
    return X.reshape(B, N * L, d)


class UPF(EKPF):
    """Particle filter whose proposal is one (optionally augmented) UKF step per particle.

    Args:
        model: the filter model, bound to a batch of B runs.
        alpha, beta, kappa: the unscented transform's parameters, for the augmented dimension
            ``n + q + r`` when ``augmented`` (else ``n``).
        augmented: put the proposal's noise into the sigma-point state.
        proposal_Q, proposal_R, **options: as for :class:`~quadest.estimators.particle_ekpf.EKPF`.
    """

    config_name = "upf"
    Params = UPFParams

    def __init__(
        self,
        model: FilterModel,
        alpha: float = 1.0,
        beta: float = 0.0,
        kappa: float = 2.0,
        augmented: bool = True,
        proposal_Q: float | None = None,
        proposal_R: float | None = None,
        **options,
    ) -> None:
        super().__init__(model, proposal_Q=proposal_Q, proposal_R=proposal_R, **options)
        self.augmented = bool(augmented)
        self.q, self.r = (model.process_noise_dim, model.measurement_noise_dim) if self.augmented else (0, 0)
        na = model.n + self.q + self.r
        if not na + kappa > 0:
            raise ConfigError("kappa", kappa, f"a number > {-na} (n + κ > 0 for the sigma-point dimension {na})")
        self.rule = UnscentedRule(float(alpha), float(beta), float(kappa))
        self._noise_factor = (np.linalg.cholesky(self.Q_proposal), np.linalg.cholesky(self.R_proposal))

    def _augment(self, L: np.ndarray) -> np.ndarray:
        """``diag(L_i, √Q_p, √R_p)`` (B, N, n + q + r, n + q + r)."""
        B, N, n, _ = L.shape
        na = n + self.q + self.r
        S = np.zeros((B, N, na, na))
        S[..., :n, :n] = L
        S[..., n : n + self.q, n : n + self.q] = self._noise_factor[0]
        S[..., n + self.q :, n + self.q :] = self._noise_factor[1]
        return S

    def proposal_moments(self, u_prev: np.ndarray, z: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One UKF step from every ``(x_i, P_i)`` with ``y_k``: ``(μ_i, P̂_i)``. Augmented: the
        points drawn once carry the noise through ``f_noise`` and ``h_noise``; otherwise new
        points are drawn from ``(x̂⁻_i, P⁻_i)``, ``P⁻_i`` including ``Q_p``, for the measurement."""
        model, x = self.model, self.x
        B, N, n = x.shape
        na = n + self.q + self.r
        wm = self.rule.mean_weights(na)
        L = self._particle_factors(self.particle_state["P"], "particle covariance")
        if self.augmented:
            X = _flat(sigma_points(self.rule, x, self._augment(L)))
            Xx = model.f_noise(X[..., :n], X[..., n : n + self.q], u_prev)
            Y = model.h_noise(Xx, X[..., n + self.q :], u)
            R = None
        else:
            Xf = model.f(_flat(sigma_points(self.rule, x, L)), u_prev).reshape(B, N, -1, n)
            x_pred, D = point_mean(Xf, wm)
            P_pred = sigma_point_covariance(self.rule, D, na, self.Q_proposal)
            Xx = _flat(sigma_points(self.rule, x_pred, self._particle_factors(P_pred, "particle covariance")))
            Y = model.h(Xx, u)
            R = self.R_proposal
        Xx, Y = Xx.reshape(B, N, -1, n), Y.reshape(B, N, Xx.shape[1] // N, -1)
        residual = model.measurement(None).residual  # a bearing's: the ⊟ of the measurement space
        (x_pred, DX), (y_pred, DY) = point_mean(Xx, wm), point_mean(Y, wm, np.add, residual)
        moments = sigma_point_moments(self.rule, DX, DY, na, y_pred, R)
        Sy = self._particle_factors(moments.cov, "proposal innovation covariance")
        conditioned = kalman_correction(model.measurement(None).innovation(z[:, None, :], y_pred), moments.cross, Sy)
        P_pred = sigma_point_covariance(self.rule, DX, na)
        return x_pred + conditioned.correction, covariance_posterior(P_pred, conditioned.gain, moments.cov)
