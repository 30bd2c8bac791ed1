"""Particle filter with an EKF proposal per particle (``estimator=ekpf``).

van der Merwe, Doucet, de Freitas & Wan (2000), "The unscented particle filter", Algorithm 1 with
the EKF as the proposal generator (§3.2, "extended Kalman particle filter"): every particle keeps
its own covariance ``P_i``; one EKF step from ``(x_i, P_i)`` with the measurement ``y_k`` gives
``(μ_i, P̂_i)``, the new particle is drawn from ``q = N(μ_i, P̂_i)``, ``P̂_i`` becomes its covariance
and travels with it through resampling. The weights use the model's true transition and
likelihood densities and the proposal density with its normaliser (``P̂_i`` differs between
particles, so ``|P̂_i|`` does not cancel).

The proposal EKF may use its own noise covariances (``proposal_Q``, ``proposal_R``: variances
q, r, covariances ``q I`` and ``r I``; default the model's ``Q`` and ``R``), as the paper does on
its benchmark. Jacobians come per particle from ``model.F_points`` and ``model.H_points``; the
step is the linearised Gaussian predict and update of the EKF (:mod:`~quadest.estimators.gaussian_steps`,
gain by triangular solves) for every particle of every run at once, and the covariance update is
Joseph's form so ``P̂_i`` stays symmetric positive semi-definite.

On a linear-Gaussian model with ``P_i = 0`` before the step, this proposal is the optimal one,
``p(x_k | x_{k−1}, y_k)``, and every particle's incremental weight equals the predictive likelihood
``N(y_k; H F x_{k−1}, H Q Hᵀ + R)`` whatever ``x_k`` was drawn (Doucet et al. 2000, §II.D).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.errors import ConfigError
from quadest.estimators.gaussian_steps import (
    joseph_covariance,
    kalman_correction,
    linearized_covariance,
    linearized_moments,
    symmetric,
)
from quadest.estimators.particle import ParticleFilter, ParticleParams
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky
from quadest.numerics.draws import standard_normals


@dataclass
class EKPFParams(ParticleParams):
    """Configuration of ``estimator=ekpf``: the shared particle options plus the proposal's noise."""

    kind: str = "ekpf"
    proposal_Q: float | None = None  # variance q of the proposal's process noise (q I); None: the model's Q
    proposal_R: float | None = None  # variance r of the proposal's measurement noise (r I); None: the model's R


def _noise_covariance(key: str, variance: float | None, default: np.ndarray) -> np.ndarray:
    """``variance · I`` of the size of ``default``, or ``default`` itself when ``variance`` is None."""
    if variance is None:
        return np.array(default, dtype=float)
    if isinstance(variance, bool) or not isinstance(variance, int | float) or not variance > 0:
        raise ConfigError(key, variance, "a variance > 0 (the covariance is variance * I), or null for the model's")
    return float(variance) * np.eye(default.shape[0])


class EKPF(ParticleFilter):
    """Particle filter whose proposal is one EKF step per particle (see the module docstring).

    Args:
        model: the filter model, bound to a batch of B runs.
        proposal_Q, proposal_R: variances ``q``, ``r`` of the proposal EKF's noise, covariances
            ``q I`` and ``r I`` (``None``: the model's ``Q``, ``R``).
        **options: the shared particle-filter options (:class:`ParticleFilter`).
    """

    config_name = "ekpf"
    Params = EKPFParams

    def __init__(
        self,
        model: FilterModel,
        proposal_Q: float | None = None,
        proposal_R: float | None = None,
        **options,
    ) -> None:
        super().__init__(model, **options)
        self.Q_proposal = _noise_covariance("proposal_Q", proposal_Q, model.Q)
        self.R_proposal = _noise_covariance("proposal_R", proposal_R, model.R)

    def initial_particle_state(self, x0: np.ndarray, P0: np.ndarray) -> dict[str, np.ndarray]:
        """Every particle starts with covariance ``P0`` of its run."""
        return {"P": np.repeat(np.asarray(P0, dtype=float)[:, None], self.N, axis=1)}

    def propose(self, u_prev: np.ndarray, z: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``x_i ~ N(μ_i, P̂_i)`` from :meth:`proposal_moments`; returns ``log N(x_i; μ_i, P̂_i)``
        and keeps ``P̂_i`` as the particle's covariance."""
        mu, P_new = self.proposal_moments(u_prev, z, u)
        N, n = mu.shape[1:]
        L = self._particle_factors(P_new, "proposal covariance")
        eps = standard_normals(self.rngs, (N, n))
        x_new = mu + (L @ eps[..., None])[..., 0]
        log_det = np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
        log_q = -0.5 * np.sum(eps**2, axis=-1) - log_det - 0.5 * n * np.log(2.0 * np.pi)
        self.particle_state["P"] = P_new
        return x_new, log_q

    def _particle_factors(self, P: np.ndarray, what: str) -> np.ndarray:
        """Lower factors (B, N, k, k) of the particles' matrices ``P`` (B, N, k, k); a run with one
        that is not positive definite is flagged (its factor is NaN there)."""
        B, N, k, _ = P.shape
        L, not_pd = batched_cholesky(P.reshape(B * N, k, k))
        bad_runs = np.flatnonzero(not_pd.reshape(B, N).any(axis=1))
        if bad_runs.size:
            self.flag(bad_runs, f"{what} not positive definite at step {self.step}")
        return L.reshape(B, N, k, k)

    def proposal_moments(self, u_prev: np.ndarray, z: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One EKF step from every ``(x_i, P_i)`` with ``y_k``: ``(μ_i, P̂_i)``, (B, N, n) and (B, N, n, n)."""
        model, x, P = self.model, self.x, self.particle_state["P"]
        x_pred = model.f(x, u_prev)
        P_pred = linearized_covariance(model.F_points(x, u_prev), P, self.Q_proposal)
        H = model.H_points(x_pred, u)
        moments = linearized_moments(model.h(x_pred, u), H, P_pred, self.R_proposal)
        Sy = self._particle_factors(symmetric(moments.cov), "proposal innovation covariance")
        conditioned = kalman_correction(
            model.measurement(None).innovation(z[:, None, :], moments.mean), moments.cross, Sy
        )
        P_new = joseph_covariance(P_pred, H, self.R_proposal, conditioned.gain)
        return x_pred + conditioned.correction, symmetric(P_new)
