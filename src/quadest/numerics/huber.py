"""Huber M-estimation measurement update (Huber 1964; Karlgaard & Schaub 2007, JGCD 30(3), §III),
batched over Monte Carlo runs; the robust step of every Gaussian filter of the package.

The update is a linear regression for the state correction ``δ = x − x̄`` (in error coordinates):

    ν = H δ + e_z,   0 = δ + e_x,   Cov(e_z) = R̄,  Cov(e_x) = P⁻,

whitened by ``R̄ = Lr Lrᵀ`` and ``P⁻ = Lp Lpᵀ``: ``y = [Lr⁻¹ ν; 0]``, ``M = [Lr⁻¹ H; Lp⁻¹]``,
residual ``ζ = y − M δ``. Huber's estimate minimises ``Σ ρ(ζ_i)`` with ρ quadratic for
``|ζ| ≤ γ`` and linear beyond (Karlgaard & Schaub eq. 23); iteratively reweighted least squares
with ``ψ(ζ) = min(1, γ/|ζ|)`` (their eqs 27–30): ``δ ← (MᵀΨM)⁻¹ MᵀΨ y``, starting from Ψ = I, and
the posterior covariance ``(MᵀΨM)⁻¹`` (their eq. 31).

``H`` and ``R̄`` for a filter whose update is given by ``Pxy`` and ``Pyy`` (statistical linear
regression, Karlgaard & Schaub eq. 34): ``H = Pxyᵀ P⁻⁻¹`` and ``R̄ = Pyy − H P⁻ Hᵀ``, the
measurement noise plus the linearisation error of the rule (Karlgaard & Schaub take ``R̄ = R``;
for an EKF, and for any filter on a linear measurement, the two are equal). With this ``R̄`` the
regression's least-squares solution is the parent filter's update exactly (``K = Pxy Pyy⁻¹``,
``P = P⁻ − K Pyy Kᵀ``), so the Huber filter differs from its parent only where a whitened
residual exceeds γ, and equals it as γ → ∞. Runs whose residuals at the Kalman solution all lie
within γ are at the IRLS fixed point after its first iteration and keep the parent's numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadest.numerics.square_root import batched_cholesky, qr_factor
from quadest.numerics.transpose import matrix_transpose as _t


@dataclass(frozen=True)
class HuberSettings:
    """Threshold γ (1.345: 95 % efficiency at the Gaussian), the IRLS iteration limit and the
    tolerance: iterations stop when no component of the correction moves by more than
    ``tolerance`` prior standard deviations (``max |Lp⁻¹ Δδ| < tolerance``)."""

    threshold: float = 1.345
    max_iterations: int = 20
    tolerance: float = 1.0e-6


def huber_weights(zeta: np.ndarray, threshold: float) -> np.ndarray:
    """``ψ(ζ)/ζ = min(1, γ/|ζ|)`` (Karlgaard & Schaub eq. 29)."""
    a = np.abs(zeta)
    return np.where(a <= threshold, 1.0, threshold / np.where(a > 0.0, a, 1.0))


def _weighted_solve(M: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(δ, C)``: the weighted least-squares solution and the lower factor ``C`` of ``MᵀΨM``."""
    MtW = _t(M) * w[..., None, :]
    C = np.linalg.cholesky(MtW @ M)
    rhs = (MtW @ y[..., None])[..., 0]
    return np.linalg.solve(_t(C), np.linalg.solve(C, rhs[..., None]))[..., 0], C


def huber_regression(
    M: np.ndarray, y: np.ndarray, settings: HuberSettings, scale: np.ndarray, start: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Huber M-estimate of ``y ≈ M δ`` (unit residual scale) by IRLS, batched.

    Args:
        M: (B, N, n) whitened regressors of full column rank; y: (B, N) whitened observations.
        settings: γ, iteration limit and tolerance.
        scale: (B, n, n) lower factor whose inverse measures the convergence step (``Lp``).
        start: (B, n) the least-squares solution if already known (the Kalman update).

    Returns:
        ``(δ, C, iterations)``: the estimate (B, n), the lower factor of ``MᵀΨM`` with the weights
        of the last solve (B, n, n), and the number of reweighted solves per run (B,).
    """
    B = M.shape[0]
    delta = _weighted_solve(M, y, np.ones(y.shape))[0] if start is None else np.array(start, dtype=float)
    C = np.linalg.cholesky(_t(M) @ M)
    iterations = np.zeros(B, dtype=int)
    active = np.arange(B)
    for _ in range(settings.max_iterations):
        if active.size == 0:
            break
        Ma, ya = M[active], y[active]
        w = huber_weights(ya - (Ma @ delta[active][..., None])[..., 0], settings.threshold)
        new, C_new = _weighted_solve(Ma, ya, w)
        step = np.linalg.solve(scale[active], (new - delta[active])[..., None])[..., 0]
        delta[active], C[active] = new, C_new
        iterations[active] += 1
        active = active[np.abs(step).max(-1) >= settings.tolerance]
    return delta, C, iterations


@dataclass
class HuberStep:
    """What a Huber update changed: ``robust`` (B,) marks the runs with a whitened residual beyond
    γ at the Kalman solution; for them ``correction`` and ``factor`` (lower factor of the posterior
    covariance) replace the parent's. ``iterations`` (B,) counts reweighted solves (0: none needed);
    ``failed`` (B,) marks runs whose ``R̄`` is not positive definite (their update is the parent's)."""

    robust: np.ndarray
    correction: np.ndarray
    factor: np.ndarray
    iterations: np.ndarray
    failed: np.ndarray
    downweighted: np.ndarray


def huber_update(
    nu: np.ndarray,
    Pxy: np.ndarray,
    Sy: np.ndarray,
    Lp: np.ndarray,
    kalman_correction: np.ndarray,
    settings: HuberSettings,
) -> HuberStep:
    """The Huber update of a filter whose Kalman update is ``kalman_correction = K ν`` (module
    docstring): innovation ``ν`` (B, m), ``Pxy`` (B, n, m), innovation factor ``Sy`` (B, m, m),
    prior factor ``Lp`` (B, n, n)."""
    B, n = kalman_correction.shape
    U = np.linalg.solve(Lp, Pxy)  # Lp⁻¹ Pxy: H P⁻ Hᵀ = Uᵀ U, H = Uᵀ Lp⁻¹
    Lr, failed = batched_cholesky(Sy @ _t(Sy) - _t(U) @ U)
    Lr[failed] = Sy[failed]
    Lp_inv = np.linalg.solve(Lp, np.broadcast_to(np.eye(n), Lp.shape))
    M = np.concatenate([np.linalg.solve(Lr, _t(U) @ Lp_inv), Lp_inv], axis=-2)
    y = np.concatenate([np.linalg.solve(Lr, nu[..., None])[..., 0], np.zeros((B, n))], axis=-1)
    zeta = y - (M @ kalman_correction[..., None])[..., 0]
    robust = (np.abs(zeta) > settings.threshold).any(-1) & ~failed
    correction = kalman_correction.copy()
    factor = np.zeros((B, n, n))
    iterations = np.zeros(B, dtype=int)
    downweighted = np.zeros(B)
    if robust.any():
        idx = np.flatnonzero(robust)
        delta, C, its = huber_regression(M[idx], y[idx], settings, Lp[idx], kalman_correction[idx])
        correction[idx], iterations[idx] = delta, its
        factor[idx] = qr_factor(np.linalg.inv(_t(C)))  # lower factor of (MᵀΨM)⁻¹ = C⁻ᵀ C⁻¹
        zeta_final = y[idx] - (M[idx] @ delta[..., None])[..., 0]
        downweighted[idx] = (np.abs(zeta_final) > settings.threshold).mean(-1)
    return HuberStep(robust, correction, factor, iterations, failed, downweighted)


class HuberCounts:
    """Per-run totals over a run's Huber updates, reported as an estimator's diagnostics."""

    def __init__(self, batch: int) -> None:
        self.updates = 0
        self.robust = np.zeros(batch)
        self.iterations = np.zeros(batch)
        self.max_iterations = np.zeros(batch)
        self.downweighted = np.zeros(batch)
        self.fallback = np.zeros(batch)

    def add(self, step: HuberStep, rows: int) -> None:
        """Count one update with ``rows`` measurement rows. An update without rows (an INS's empty
        primary measurement, docs/ins.md) has nothing to downweight and is not counted, so the
        fractions are per update that measured something."""
        if rows == 0:
            return
        self.updates += 1
        self.robust += step.robust
        self.iterations += step.iterations
        self.max_iterations = np.maximum(self.max_iterations, step.iterations)
        self.downweighted += step.downweighted
        self.fallback += step.failed

    def diagnostics(self) -> dict[str, np.ndarray]:
        """Mean and largest IRLS iterations per update, the fraction of updates with an outlying
        residual, the mean fraction of residuals still beyond γ in those, and the number of
        updates left to the Kalman step because ``R̄`` was not positive definite."""
        updates = max(self.updates, 1)
        return {
            "huber_iterations_mean": self.iterations / updates,
            "huber_iterations_max": self.max_iterations.copy(),
            "huber_robust_fraction": self.robust / updates,
            "huber_downweighted_fraction": self.downweighted / np.maximum(self.robust, 1.0),
            "huber_fallback_updates": self.fallback.copy(),
        }
