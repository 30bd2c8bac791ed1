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
:class:`~quadest.numerics.rules.UnscentedRule`, for all particles of all runs in one model call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.errors import ConfigError
from quadest.estimators.params import ranged
from quadest.estimators.particle import check_ranges
from quadest.estimators.particle_ekpf import EKPF, EKPFParams
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky
from quadest.numerics.rules import UnscentedRule, rule_mean


@dataclass
class UPFParams(EKPFParams):
    """Configuration of ``estimator=upf``: the EKPF's options plus the UT's and ``augmented``."""

    kind: str = "upf"
    alpha: float = ranged(1.0, "spread of the sigma points", gt=0.0)
    beta: float = ranged(0.0, "prior knowledge of the distribution; 2 is optimal for a Gaussian")
    kappa: float = ranged(2.0, "secondary scaling; n + kappa > 0 for the sigma-point dimension")
    augmented: bool = True


def _swap(a: np.ndarray) -> np.ndarray:
    return np.swapaxes(a, -1, -2)


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
        check_ranges(UPFParams, {"alpha": alpha, "beta": beta, "kappa": kappa}, model.n)
        if not na + kappa > 0:
            raise ConfigError("kappa", kappa, f"a number > {-na} (n + κ > 0 for the sigma-point dimension {na})")
        self.rule = UnscentedRule(float(alpha), float(beta), float(kappa))
        self._noise_factor = (np.linalg.cholesky(self.Q_proposal), np.linalg.cholesky(self.R_proposal))

    def _factor(self, P: np.ndarray) -> np.ndarray:
        """Lower factors (B, N, n, n) of the particles' covariances; a run with one that is not
        positive definite is flagged."""
        B, N, n, _ = P.shape
        L, not_pd = batched_cholesky(P.reshape(B * N, n, n))
        bad_runs = np.flatnonzero(not_pd.reshape(B, N).any(axis=1))
        if bad_runs.size:
            self.flag(bad_runs, f"particle covariance not positive definite at step {self.step}")
        return L.reshape(B, N, n, n)

    def _augment(self, L: np.ndarray) -> np.ndarray:
        """``diag(L_i, √Q_p, √R_p)`` (B, N, n + q + r, n + q + r)."""
        B, N, n, _ = L.shape
        na = n + self.q + self.r
        S = np.zeros((B, N, na, na))
        S[..., :n, :n] = L
        S[..., n : n + self.q, n : n + self.q] = self._noise_factor[0]
        S[..., n + self.q :, n + self.q :] = self._noise_factor[1]
        return S

    def _points(self, mean: np.ndarray, S: np.ndarray) -> np.ndarray:
        """Sigma points (B, N·L, d) of every particle: ``[mean; 0; 0]`` plus the rule's offsets of ``S``."""
        B, N, n = mean.shape
        offsets = self.rule.offsets(S)
        L, d = offsets.shape[-2:]
        X = offsets.reshape(B, N * L, d)
        X[..., :n] += np.repeat(mean, L, axis=1)
        return X

    def proposal_moments(self, u_prev: np.ndarray, z: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One UKF step from every ``(x_i, P_i)`` with ``y_k``: ``(μ_i, P̂_i)``. Augmented: the
        points drawn once carry the noise through ``f_noise`` and ``h_noise``; otherwise new
        points are drawn from ``(x̂⁻_i, P⁻_i)``, ``P⁻_i`` including ``Q_p``, for the measurement."""
        model, x = self.model, self.x
        B, N, n = x.shape
        na = n + self.q + self.r
        wm = self.rule.mean_weights(na)
        L = self._factor(self.particle_state["P"])
        if self.augmented:
            X = self._points(x, self._augment(L))
            Xx = model.f_noise(X[..., :n], X[..., n : n + self.q], u_prev)
            Y = model.h_noise(Xx, X[..., n + self.q :], u)
        else:
            Xf = model.f(self._points(x, L), u_prev).reshape(B, N, -1, n)
            x_pred = rule_mean(Xf, wm)
            P_pred = self.rule.covariance(Xf - x_pred[..., None, :], na) + self.Q_proposal
            Xx = self._points(x_pred, self._factor(P_pred))
            Y = model.h(Xx, u)
        Xx, Y = Xx.reshape(B, N, -1, n), Y.reshape(B, N, Xx.shape[1] // N, -1)
        x_pred, y_pred = rule_mean(Xx, wm), rule_mean(Y, wm)
        DX, DY = Xx - x_pred[..., None, :], Y - y_pred[..., None, :]
        P_pred = self.rule.covariance(DX, na)
        Pyy = self.rule.covariance(DY, na) + (0.0 if self.augmented else self.R_proposal)
        gain = _swap(np.linalg.solve(Pyy, _swap(self.rule.cross_covariance(DX, DY, na))))
        mu = x_pred + (gain @ (z[:, None, :] - y_pred)[..., None])[..., 0]
        P_new = P_pred - gain @ Pyy @ _swap(gain)
        return mu, 0.5 * (P_new + _swap(P_new))
