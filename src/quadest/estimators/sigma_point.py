"""The sigma-point family: one covariance-form filter and one square-root filter, each taking any
integration rule (:mod:`quadest.numerics.rules`), batched over Monte Carlo runs.

- :class:`SigmaPointKalmanFilter` keeps ``P``; with the UT it is the UKF, with central differences
  the CDKF (Nørgaard et al. 2000), with cubature the CKF (Arasaratnam & Haykin 2009).
- :class:`SquareRootSigmaPointFilter` keeps a lower factor ``S`` (``P = S Sᵀ``) and is the thesis's
  SR-UKF (seed 000, chapter 5, eqs 5.12–5.29) with the rule's points and columns in place of the
  UT's: QR of the rule's columns and the noise factor (5.18, 5.23), the rule's rank-one terms
  (5.19, 5.24), the gain by two triangular solves (5.26) and the posterior downdate by ``K Sy``
  (5.28–5.29), unless the rule gives its own posterior columns (central differences: no downdate).

Both take ``augmented=True`` (van der Merwe 2004; the EKF/UKF toolbox's "UKF2"): the
process and measurement noise join the sigma-point state ``[x; w; v]`` (dimension n + q + r),
the points are drawn once per step in the time update and reused in the measurement update, and
the model's ``f_noise``/``h_noise`` take the noise (for models whose noise is not additive). A
second update in the same step (another sensor) draws ``[x; v]`` afresh.

States that are not vectors: points are ``x ⊞ offset`` and deviations ``Y ⊟ ȳ`` with the model's
``boxplus``/``boxminus``; the mean is ``Y0 ⊞ Σ wm_i (Y_i ⊟ Y0)``.

The points, means, covariance-form moments, gain and correction are the shared Gaussian steps
(:mod:`quadest.estimators.gaussian_steps`); the square-root form keeps the same moments as factors.

The step from the moments (``ν``, ``Pxy``, ``Pyy``) to the posterior is one hook,
:meth:`SigmaPointFilter._measurement_update`: the Kalman update, or with ``huber`` settings the
Huber M-estimation update (Karlgaard & Schaub 2007; :mod:`quadest.numerics.huber`) for the runs
with a whitened residual beyond γ. The innovation and its factor (NIS) stay the parent's: the
sigma-point ``Pyy`` with the nominal R.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import ClassVar

import numpy as np

from quadest.errors import ConfigError, DowndateError
from quadest.estimators.base import Estimator
from quadest.estimators.gaussian_steps import (
    covariance_posterior,
    kalman_correction,
    point_mean,
    sigma_point_covariance,
    sigma_points,
)
from quadest.estimators.smoothing import SmootherStep, SmoothingForm, sigma_point_smoother_gain
from quadest.models.base import FilterModel
from quadest.numerics import batched_cholesky, cholupdate, psd_sqrt, qr_factor
from quadest.numerics import matrix_transpose as _t
from quadest.numerics.huber import HuberCounts, HuberSettings
from quadest.numerics.rules import IntegrationRule


def _block_diagonal(blocks: list[np.ndarray]) -> np.ndarray:
    """Block-diagonal stack of (B, ni, ni) blocks → (B, Σni, Σni)."""
    B = blocks[0].shape[0]
    size = sum(b.shape[-1] for b in blocks)
    out = np.zeros((B, size, size))
    i = 0
    for b in blocks:
        k = b.shape[-1]
        out[:, i : i + k, i : i + k] = b
        i += k
    return out


class SigmaPointFilter(Estimator):
    """What the covariance and square-root forms share: the rule, the points, the mean, the gain,
    the augmented bookkeeping. A form defines how its second moment is stored and updated."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "smoothing"})

    def __init__(
        self, model: FilterModel, rule: IntegrationRule, augmented: bool = False, huber: HuberSettings | None = None
    ) -> None:
        super().__init__(model)
        self.huber = huber
        if augmented and not model.supports_augmented:
            raise ValueError(f"model '{model.name}' does not support augmented: true (its noise cannot join the state)")
        self.rule = rule
        self.augmented = bool(augmented)
        self.sqrt_Q = psd_sqrt(model.Q, "Q")  # Sv = √Rv (5.14)
        self.sqrt_R = psd_sqrt(model.R, "R")  # Sn = √Rn (5.14)
        n, q, r = model.n_err, model.process_noise_dim, model.measurement_noise_dim
        dim = n + q + r if augmented else n
        try:
            rule.validate(dim)
        except ValueError as exc:  # a configuration the rule cannot serve: the job fails, no run "diverges"
            raise ConfigError(f"{type(self).config_name}.rule", rule.name, f"{exc} (dimension {dim})") from None
        self._sensor_cache: dict[str, np.ndarray] = {}

    # --- the form: how the second moment (its "spread": covariance or factor) is kept ---

    @abstractmethod
    def _set_spread_from_P0(self, P0: np.ndarray) -> None:
        """Start the spread from the initial covariance (B, n, n)."""

    @abstractmethod
    def _spread_state(self) -> np.ndarray:
        """The stored spread (B, n, n): covariance or lower factor."""

    @abstractmethod
    def _set_spread(self, spread: np.ndarray) -> None:
        """Store a new spread."""

    @abstractmethod
    def _factor(self) -> np.ndarray:
        """Lower factor of the current covariance (B, n, n)."""

    @abstractmethod
    def _spread(self, D: np.ndarray, dim: int, sqrt_noise: np.ndarray | None) -> np.ndarray:
        """The spread of deviations ``D`` (B, L, m) of points of dimension ``dim``, plus the
        additive noise given by its factor."""

    @abstractmethod
    def _innovation_factor(self, spread_y: np.ndarray) -> np.ndarray:
        """Lower factor of the innovation covariance from its spread."""

    @abstractmethod
    def _posterior(self, K, spread_y, DX, DY, dim: int, sqrt_R: np.ndarray | None) -> None:
        """Posterior spread after the gain ``K`` (eqs 5.28–5.29)."""

    @abstractmethod
    def _set_factor(self, runs: np.ndarray, factor: np.ndarray) -> None:
        """Store the posterior of ``runs`` given by its lower factor (the Huber update's)."""

    # --- shared steps ---

    def initialize(self, x0: np.ndarray, P0: np.ndarray) -> None:
        """x̂0 = E[x0] (5.12) and the spread from P0 (5.13)."""
        self.x = np.array(x0, dtype=float, copy=True)
        B = self.x.shape[0]
        self._reset_failures(B)
        self._set_spread_from_P0(np.asarray(P0, dtype=float))
        self._x_safe, self._spread_safe = self.x.copy(), self._spread_state().copy()
        self._nu = np.zeros((B, self.model.m))
        self._Sy = np.broadcast_to(self.sqrt_R, (B, *self.sqrt_R.shape)).copy()
        self._carried: tuple[np.ndarray, np.ndarray, int] | None = None
        self._huber_counts = HuberCounts(B)

    def _broadcast(self, M: np.ndarray) -> np.ndarray:
        return np.broadcast_to(M, (self.x.shape[0], *M.shape))

    def _points(self, noise_factors: list[np.ndarray]) -> np.ndarray:
        """Points (B, L, n + Σ noise dims): ``x ⊞ offset`` for the state part, the noise parts as
        offsets from zero (eqs 5.15, 5.20; augmented: van der Merwe 2004)."""
        S = self._factor()
        if noise_factors:
            S = _block_diagonal([S, *(self._broadcast(F) for F in noise_factors)])
        return sigma_points(self.rule, self.x, S, self.model.boxplus)

    def _mean(self, Y: np.ndarray, dim: int, state: bool) -> tuple[np.ndarray, np.ndarray]:
        """Weighted mean and deviations of points ``Y`` (B, L, ·) (eqs 5.8, 5.17, 5.22)."""
        wm = self.rule.mean_weights(dim)
        if not state:
            return point_mean(Y, wm)
        return point_mean(Y, wm, self.model.boxplus, self.model.boxminus)

    def predict(self, u: np.ndarray) -> None:
        """Time update (eqs 5.15–5.19); with smoothing on, also the step of the unscented RTS
        smoother (:mod:`~quadest.estimators.smoothing`) from the same points."""
        ns, q = self.model.n, self.model.process_noise_dim
        x_prior = self.x
        if self.augmented:
            X = self._points([self.sqrt_Q, self.sqrt_R])
            dim = self.model.n_err + q + self.model.measurement_noise_dim
            X_pred = self.model.f_noise(X[..., :ns], X[..., ns : ns + q], u)
            self._carried = (X_pred, X[..., ns + q :], dim)
            sqrt_noise = None
        else:
            X = self._points([])  # (5.15)
            X_pred = self.model.f(X, u)  # (5.16)
            dim, sqrt_noise = self.model.n_err, self.sqrt_Q
        self.x, D = self._mean(X_pred, dim, state=True)  # (5.17)
        self._set_spread(self._spread(D, dim, sqrt_noise))  # (5.18)–(5.19)
        if self.smoothing:
            self._record_smoother_step(self.model.boxminus(X[..., :ns], x_prior[:, None, :]), D, dim, sqrt_noise)
        self.quarantine(self.x, self._spread_state(), self._x_safe, self._spread_safe)

    def _record_smoother_step(self, DX: np.ndarray, D: np.ndarray, dim: int, sqrt_noise: np.ndarray | None) -> None:
        """The smoother step of this predict from the points' deviations before (``DX``) and after
        (``D``) the model, in this filter's form: ``Z`` is the spread of ``DX − G D`` plus ``G √Q``."""
        G, E = sigma_point_smoother_gain(self.rule, DX, D, dim, self._factor())
        noise = None if sqrt_noise is None else G @ sqrt_noise
        self.smoother_step = SmootherStep(G, self.x.copy(), self._spread(E, dim, noise))

    def smoothing_form(self) -> SmoothingForm:
        """This filter's form for the smoother: square root or covariance, the model's ⊞/⊟ on a
        manifold state (no reset Jacobian: the family applies none)."""
        manifold = self.model.has_manifold_state
        return SmoothingForm(
            square_root="sqrt_covariance" in self.capabilities,
            boxplus=self.model.boxplus if manifold else None,
            boxminus=self.model.boxminus if manifold else None,
        )

    def _sensor(self, sensor: str | None):
        """``(h, sqrt_R, h_noise, residual)`` of the primary measurement or of
        ``model.sensors[sensor]``; ``residual`` is ``None`` for plain subtraction."""
        meas = self.model.measurement(sensor)
        if sensor is None:
            return self.model.h, self.sqrt_R, self.model.h_noise, meas.residual
        if sensor not in self._sensor_cache:
            self._sensor_cache[sensor] = psd_sqrt(meas.R, f"R of sensor '{sensor}'")
        h = meas.h
        return h, self._sensor_cache[sensor], lambda x, v, u: h(x, u) + v, meas.residual

    def update(self, z: np.ndarray, u: np.ndarray, sensor: str | None = None) -> None:
        """Measurement update (eqs 5.20–5.29), with the primary measurement or a named sensor. A
        measurement with its own ``residual`` ``r`` (a bearing) takes it as the ⊟ of its space:
        ``ȳ = Y_0 + Σ wm_i r(Y_i, Y_0)``, deviations ``r(Y_i, ȳ)`` and ``ν = r(z, ȳ)``, so points on
        both sides of a wrap average to the right angle (as
        :class:`~quadest.estimators.integrations.StatisticalLinearRegression`)."""
        ns = self.model.n
        h, sqrt_R, h_noise, residual = self._sensor(sensor)
        if self.augmented:
            if self._carried is None or sensor is not None:
                X = self._points([sqrt_R])
                self._carried = (X[..., :ns], X[..., ns:], self.model.n_err + sqrt_R.shape[0])
            X, V, dim = self._carried
            self._carried = None
            Y = h_noise(X, V, u)
            sqrt_R = None
        else:
            X = self._points([])  # (5.20) redraw
            Y = h(X, u)  # (5.21)
            dim = self.model.n_err
        if residual is None:
            y_pred, DY = self._mean(Y, dim, state=False)  # (5.22)
        else:
            y_pred, DY = point_mean(Y, self.rule.mean_weights(dim), np.add, residual)
        spread_y = self._spread(DY, dim, sqrt_R)  # (5.23)–(5.24)
        Sy = self._innovation_factor(spread_y)
        DX = self.model.boxminus(X, self.x[:, None, :])
        Pxy = self.rule.cross_covariance(DX, DY, dim)  # (5.25)
        self._nu, self._Sy = (z - y_pred if residual is None else residual(z, y_pred)), Sy
        self._measurement_update(Pxy, spread_y, DX, DY, dim, sqrt_R)
        self.quarantine(self.x, self._spread_state(), self._x_safe, self._spread_safe)

    def _measurement_update(self, Pxy, spread_y, DX, DY, dim: int, sqrt_R: np.ndarray | None) -> None:
        """From the moments to the posterior: gain (5.26), mean (5.27) and spread (5.28)–(5.29);
        with ``huber`` settings, the runs with an outlying whitened residual take the Huber
        M-estimate and its covariance instead (:func:`~quadest.numerics.huber.huber_update`)."""
        prior_factor = None if self.huber is None else self._factor()
        conditioned = kalman_correction(self._nu, Pxy, self._Sy, self.huber, prior_factor)  # (5.26)
        self.x = self.model.boxplus(self.x, conditioned.correction)  # (5.27)
        self._posterior(conditioned.gain, spread_y, DX, DY, dim, sqrt_R)  # (5.28)–(5.29)
        step = conditioned.huber
        if step is not None:
            if step.robust.any():
                self._set_factor(np.flatnonzero(step.robust), step.factor[step.robust])
            self._huber_counts.add(step, self._nu.shape[-1])

    def diagnostics(self) -> dict[str, np.ndarray]:
        """With Huber settings, the IRLS counts per run (:class:`~quadest.numerics.huber.HuberCounts`)."""
        return {} if self.huber is None else self._huber_counts.diagnostics()

    @property
    def mean(self) -> np.ndarray:
        return self.x

    def innovation(self) -> tuple[np.ndarray, np.ndarray]:
        return self._nu, self._Sy


class SigmaPointKalmanFilter(SigmaPointFilter):
    """Covariance form: ``P⁻ = Σ wc_i D_i D_iᵀ + Q`` (or the rule's columns), ``P = P⁻ − K Pyy Kᵀ``.
    A run whose covariance stops being positive definite (the fifth-degree rule's negative
    weights can do that) is flagged when it is next factorised."""

    def _set_spread_from_P0(self, P0: np.ndarray) -> None:
        self.P = P0.copy()

    def _spread_state(self) -> np.ndarray:
        return self.P

    def _set_spread(self, spread: np.ndarray) -> None:
        self.P = spread

    def _factor(self) -> np.ndarray:
        S, bad = batched_cholesky(self.P)
        if bad.any():
            self.flag(np.flatnonzero(bad), "covariance not positive definite")
            S[bad] = np.linalg.cholesky(self._spread_safe[bad])
        return S

    def _spread(self, D: np.ndarray, dim: int, sqrt_noise: np.ndarray | None) -> np.ndarray:
        return sigma_point_covariance(self.rule, D, dim, None if sqrt_noise is None else sqrt_noise @ _t(sqrt_noise))

    def _innovation_factor(self, Pyy: np.ndarray) -> np.ndarray:
        Sy, bad = batched_cholesky(Pyy)
        if bad.any():
            self.flag(np.flatnonzero(bad), "innovation covariance not positive definite")
            # a flagged run is quarantined after the update: its factor only has to be finite and of this
            # measurement's size (the primary measurement's last factor, or I for a named sensor of another size)
            Sy[bad] = self._Sy[bad] if self._Sy.shape[-1] == Sy.shape[-1] else np.eye(Sy.shape[-1])
        return Sy

    def _posterior(self, K, Pyy, DX, DY, dim: int, sqrt_R: np.ndarray | None) -> None:
        self.P = covariance_posterior(self.P, K, Pyy)

    def _set_factor(self, runs: np.ndarray, factor: np.ndarray) -> None:
        self.P[runs] = factor @ _t(factor)

    @property
    def covariance(self) -> np.ndarray:
        return self.P


class SquareRootSigmaPointFilter(SigmaPointFilter):
    """Square-root form, the thesis's algorithm (eqs 5.12–5.29) for any rule. A downdate that would
    make a covariance indefinite flags its run (:class:`~quadest.errors.DowndateError`)."""

    capabilities: ClassVar[frozenset[str]] = frozenset({"innovation", "sqrt_covariance", "smoothing"})

    def _set_spread_from_P0(self, P0: np.ndarray) -> None:
        self.S = np.linalg.cholesky(P0)  # Sx0 = chol(P0) (5.13)

    def _spread_state(self) -> np.ndarray:
        return self.S

    def _set_spread(self, spread: np.ndarray) -> None:
        self.S = spread

    def _factor(self) -> np.ndarray:
        return self.S

    def _cholupdate(self, S: np.ndarray, u: np.ndarray, sign: float) -> np.ndarray:
        try:
            return cholupdate(S, u, sign)
        except DowndateError as err:
            self.flag(err.runs, err.reason)
            return err.result

    def _spread(self, D: np.ndarray, dim: int, sqrt_noise: np.ndarray | None) -> np.ndarray:
        """qr{[rule columns, √noise]} then the rule's rank-one terms (5.18–5.19, 5.23–5.24)."""
        A = self.rule.sqrt_columns(D, dim)
        if sqrt_noise is not None:
            A = np.concatenate([A, np.broadcast_to(sqrt_noise, (*A.shape[:-1], sqrt_noise.shape[-1]))], axis=-1)
        S = qr_factor(A)
        for cols, sign in self.rule.rank_one_terms(D, dim):
            S = self._cholupdate(S, cols, sign)
        return S

    def _innovation_factor(self, Sy: np.ndarray) -> np.ndarray:
        return Sy

    def _posterior(self, K, Sy, DX, DY, dim: int, sqrt_R: np.ndarray | None) -> None:
        cols = self.rule.posterior_columns(DX, DY, K, dim)
        if cols is None:
            self.S = self._cholupdate(self.S, K @ Sy, -1.0)  # U = K Sy (5.28), (5.29)
            return
        if sqrt_R is not None:
            cols = np.concatenate([cols, K @ sqrt_R], axis=-1)
        self.S = qr_factor(cols)

    def _set_factor(self, runs: np.ndarray, factor: np.ndarray) -> None:
        self.S[runs] = factor

    @property
    def covariance(self) -> np.ndarray:
        return self.S @ _t(self.S)

    @property
    def sqrt_covariance(self) -> np.ndarray:
        return self.S
