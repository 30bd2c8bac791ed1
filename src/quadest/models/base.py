"""The filter-model interface every estimator works through.

A filter model is the discrete-time system ``x_k = f(x_{k-1}, u_{k-1}) + v``,
``z_k = h(x_k, u_k) + n`` (thesis eqs 5.10–5.11, 5.32) with ``v ~ N(0, Q)``, ``n ~ N(0, R)``,
bound to one batch of ``B`` Monte Carlo runs: per-run parameters (for example the calibrated
sensor errors of each run) carry a leading batch axis.

Shapes (the contract every estimator relies on):

- ``f(x, u)``: ``x`` (B, K, n), ``u`` (B, nu) → (B, K, n). ``K`` is any number of points per run
  (2n+1 sigma points, one EKF mean, ...): all points of all runs go through in one call.
- ``h(x, u)``: ``x`` (B, K, n), ``u`` (B, nu) → (B, K, m).
- ``F(x, u)``: ``x`` (B, n) → (B, n, n), the Jacobian of ``f``; ``H(x, u)`` → (B, m, n).
  Models with analytic Jacobians override :meth:`FilterModel.F_analytic` and
  :meth:`FilterModel.H_analytic`; the others fall back to central differences.
- ``Q`` (n, n) and ``R`` (m, m) are shared by the runs of a batch.

Some formulations carry *companion* quantities propagated outside the filter from its estimate,
as the thesis does with the Euler angles (§5.3.1: "integrate X_k to obtain position and
angles"). The runner keeps them per estimator and run with :meth:`companion_step` and feeds them
to ``f`` and ``h`` through :meth:`filter_input`.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod

import numpy as np


class FilterModel(ABC):
    """Discrete-time model of a state-estimation problem, bound to a batch of runs."""

    name: str = "model"
    n: int
    m: int
    nu: int
    dt: float
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    measurement_names: tuple[str, ...]
    companion_names: tuple[str, ...] = ()
    companion_units: tuple[str, ...] = ()
    Q: np.ndarray
    R: np.ndarray
    batch_size: int = 1
    fd_step: float = 1e-6

    @abstractmethod
    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """State transition, ``x`` (B, K, n), ``u`` (B, nu) → (B, K, n)."""

    @abstractmethod
    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Measurement function, ``x`` (B, K, n), ``u`` (B, nu) → (B, K, m)."""

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        """Analytic Jacobian of ``f`` at ``x`` (B, n), or ``None`` when the model has none."""
        return None

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        """Analytic Jacobian of ``h`` at ``x`` (B, n), or ``None`` when the model has none."""
        return None

    def F(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobian of ``f`` (B, n, n): analytic when the model has it, else central differences."""
        J = self.F_analytic(x, u)
        return J if J is not None else self.jacobian_fd(self.f, x, u)

    def H(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Jacobian of ``h`` (B, m, n): analytic when the model has it, else central differences."""
        J = self.H_analytic(x, u)
        return J if J is not None else self.jacobian_fd(self.h, x, u)

    def jacobian_fd(self, fun, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Central-difference Jacobian of ``fun`` at ``x`` (B, n): all 2n points in one call."""
        n = x.shape[-1]
        step = self.fd_step * np.maximum(1.0, np.abs(x))
        E = np.eye(n)[None] * step[:, None, :]
        pts = np.concatenate([x[:, None, :] + E, x[:, None, :] - E], axis=1)
        y = fun(pts, u)
        return np.swapaxes((y[:, :n] - y[:, n:]) / (2.0 * step[:, :, None]), -1, -2)

    # --- companion quantities (thesis: angles and positions integrated outside the filter) ---

    def filter_input(self, u: np.ndarray, companion: np.ndarray) -> np.ndarray:
        """The input ``f`` and ``h`` receive: the measured input plus any companion values."""
        return u

    def companion_step(self, companion: np.ndarray, x_post: np.ndarray) -> np.ndarray:
        """Advance the companion values one sample from the posterior estimate ``x_post`` (B, n)."""
        return companion

    # --- batches ---

    def _per_run_arrays(self) -> tuple[str, ...]:
        """Names of attributes that carry a leading batch axis."""
        return ()

    def select(self, runs: int | slice | np.ndarray) -> FilterModel:
        """A copy of the model bound to a subset of the batch (an int gives a batch of one)."""
        idx = slice(runs, runs + 1) if isinstance(runs, int | np.integer) else runs
        other = copy.copy(self)
        for name in self._per_run_arrays():
            setattr(other, name, getattr(self, name)[idx])
        other.batch_size = len(np.arange(self.batch_size)[idx])
        return other
