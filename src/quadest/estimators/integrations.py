"""Linearisation as an integration: how a Gaussian filter turns a nonlinear map into an affine one.

Särkkä & Svensson (2023, *Bayesian Filtering and Smoothing*, 2nd ed.) write every Gaussian filter
of the family as one filter over *enabling approximations*: near the Gaussian ``N(m, P)`` a map
``g`` (the transition ``f`` or a measurement ``h``) is replaced by the affine model

    g(x) ≈ ḡ + A (x ⊟ m) + e,   e ~ N(0, Λ),

and the Kalman filter's predict and update run on it (their §9.1–§9.4, §10.1–§10.3). Two ways to
choose ``(ḡ, A, Λ)`` are the two :class:`Linearisation` s here:

- :class:`Taylor`: first-order Taylor expansion at ``m``: ``ḡ = g(m)``, ``A`` the Jacobian of
  ``g`` at ``m``, ``Λ`` the noise covariance (the EKF; eqs 7.6–7.7 of the book);
- :class:`StatisticalLinearRegression`: the statistical linear regression of ``g`` over
  ``N(m, P)`` with any sigma-point rule (:mod:`quadest.numerics.rules`): ``ḡ = E[g(x)]``,
  ``A = C_xgᵀ P⁻¹``, ``Λ = Cov[g(x)] + noise − A P Aᵀ`` (eqs 9.4–9.6): the UKF, CKF, fifth-degree
  CKF and Gauss–Hermite KF are this with their rule.

An :class:`Integration` is a linearisation with a number of ``iterations`` of the measurement
update: each iteration linearises again about the posterior of the previous one and conditions
the *prior* on the new affine model (``tolerance`` stops a run early when its mean moved less).
One iteration is the plain filter; iterated Taylor is the iterated EKF (Gauss–Newton on the MAP
problem, Bell & Cathey 1993; the book's Algorithm 7.9) and iterated statistical linear regression
is the iterated posterior-linearisation filter (IPLF, García-Fernández, Svensson, Morelande &
Särkkä 2015; the book's Algorithm 10.11). The filter that uses them is
:class:`~quadest.estimators.gaussian_filter.GaussianFilter`; the smoothers that re-linearise a
whole trajectory are in :mod:`quadest.estimators.iterated_smoothing`.

Shapes: means (B, n), covariances (B, n_err, n_err), the affine model's ``ḡ`` (B, d), ``A``
(B, d_err, n_err) and ``Λ`` (B, d_err, d_err). A factorisation that fails goes through the
``factor`` callable the filter hands in, which flags the run and returns a usable factor.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from quadest.estimators.gaussian_steps import point_mean, sigma_points, symmetric
from quadest.models.base import FilterModel
from quadest.numerics import kalman_gain
from quadest.numerics import matrix_transpose as _t
from quadest.numerics.rules import IntegrationRule

Factor = Callable[[np.ndarray, str], np.ndarray]


@dataclass(frozen=True)
class AffineModel:
    """``g(x) ≈ mean + A (x ⊟ m) + e``, ``e ~ N(0, noise)``, about the linearisation point ``m``."""

    mean: np.ndarray
    jacobian: np.ndarray
    noise: np.ndarray


class Linearisation(Protocol):
    """How a map is made affine near ``N(m, P)`` (module docstring)."""

    name: str

    def transition(
        self, model: FilterModel, m: np.ndarray, P: np.ndarray, u: np.ndarray, factor: Factor
    ) -> AffineModel:
        """The affine transition about ``N(m, P)``; ``noise`` includes ``Q``."""

    def measurement(
        self, model: FilterModel, sensor: str | None, m: np.ndarray, P: np.ndarray, u: np.ndarray, factor: Factor
    ) -> AffineModel:
        """The affine measurement (the primary one, or ``sensor`` of ``model.sensors``) about
        ``N(m, P)``; ``noise`` includes the measurement's ``R``."""


@dataclass(frozen=True)
class Taylor:
    """First-order Taylor expansion at the mean (the EKF's): ``ḡ = g(m)``, ``A = ∂g/∂δ`` on the
    error state (the model's ``F_err``/``H_err``), ``Λ`` = the noise covariance."""

    name: str = "taylor"

    def transition(
        self, model: FilterModel, m: np.ndarray, P: np.ndarray, u: np.ndarray, factor: Factor
    ) -> AffineModel:
        B = m.shape[0]
        F = model.F_err(m, u)
        return AffineModel(model.f(m[:, None, :], u)[:, 0], F, np.broadcast_to(model.Q, (B, *model.Q.shape)))

    def measurement(
        self, model: FilterModel, sensor: str | None, m: np.ndarray, P: np.ndarray, u: np.ndarray, factor: Factor
    ) -> AffineModel:
        B, meas = m.shape[0], model.measurement(sensor)
        H = model.H_err(m, u, sensor)
        return AffineModel(meas.h(m[:, None, :], u)[:, 0], H, np.broadcast_to(meas.R, (B, *meas.R.shape)))


@dataclass(frozen=True)
class StatisticalLinearRegression:
    """Statistical linear regression over ``N(m, P)`` with a sigma-point ``rule`` (the book's
    eqs 9.4–9.6): points ``m ⊞ S ξ_i``, ``ḡ = Σ wm_i g_i``, ``C = Σ wc_i (X_i ⊟ m)(g_i ⊟ ḡ)ᵀ``,
    ``A = Cᵀ P⁻¹`` (two triangular solves against ``S``), ``Λ = Σ wc_i D_i D_iᵀ + noise − A P Aᵀ``.
    A measurement with its own ``residual`` (a bearing) takes it as the ⊟ of its space: the mean
    is ``Y_0 + Σ wm_i r(Y_i, Y_0)`` and the deviations ``D_i = r(Y_i, ȳ)``, so points on both
    sides of a wrap average to the right angle."""

    rule: IntegrationRule
    name: str = "slr"

    def _regression(self, model, g, m, P, noise, factor, boxplus, boxminus) -> AffineModel:
        S = factor(P, "covariance")
        X = sigma_points(self.rule, m, S, model.boxplus)
        mean, D = point_mean(g(X), self.rule.mean_weights(model.n_err), boxplus, boxminus)
        C = self.rule.cross_covariance(model.boxminus(X, m[:, None, :]), D, model.n_err)
        A = kalman_gain(_t(C), S)
        cov = self.rule.covariance(D, model.n_err) + noise
        return AffineModel(mean, A, symmetric(cov - A @ P @ _t(A)))

    def transition(
        self, model: FilterModel, m: np.ndarray, P: np.ndarray, u: np.ndarray, factor: Factor
    ) -> AffineModel:
        return self._regression(model, lambda X: model.f(X, u), m, P, model.Q, factor, model.boxplus, model.boxminus)

    def measurement(
        self, model: FilterModel, sensor: str | None, m: np.ndarray, P: np.ndarray, u: np.ndarray, factor: Factor
    ) -> AffineModel:
        meas = model.measurement(sensor)
        if meas.residual is None:
            return self._regression(model, lambda X: meas.h(X, u), m, P, meas.R, factor, None, None)
        return self._regression(model, lambda X: meas.h(X, u), m, P, meas.R, factor, np.add, meas.residual)


@dataclass(frozen=True)
class Integration:
    """A linearisation and how often the measurement update re-linearises about its posterior
    (module docstring): ``iterations`` ≥ 1; a run stops early once its mean moved by no more than
    ``tolerance`` (max-norm of the error-state step) in an iteration."""

    linearisation: Taylor | StatisticalLinearRegression
    iterations: int = 1
    tolerance: float = 0.0

    def __post_init__(self) -> None:
        if (
            isinstance(self.iterations, bool)
            or not isinstance(self.iterations, int | np.integer)
            or self.iterations < 1
        ):
            raise ValueError(f"iterations must be an integer >= 1, got {self.iterations!r}")
        if not (np.isfinite(self.tolerance) and self.tolerance >= 0.0):
            raise ValueError(f"tolerance must be a finite number >= 0, got {self.tolerance!r}")
