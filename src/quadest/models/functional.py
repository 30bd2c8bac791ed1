"""Filter models from plain functions, and the linear-Gaussian model.

:class:`FunctionalModel` wraps vectorised ``f(x, u)`` and ``h(x, u)`` (shapes as in
:mod:`quadest.models.base`) into a :class:`FilterModel`: the quickest way to put an estimator on a
new problem. :class:`LinearGaussianModel` is ``x⁺ = A x + Bu u + v``, ``z = C x + n``, on which
every Gaussian filter must reproduce the Kalman filter.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from quadest.models.base import FilterModel


class FunctionalModel(FilterModel):
    """A filter model from vectorised functions ``f(x, u)`` and ``h(x, u)``.

    Args:
        f, h: model functions; ``x`` (B, K, n), ``u`` (B, nu).
        Q, R: noise covariances (n, n) and (m, m).
        nu: input dimension (0 allowed: pass ``u`` of shape (B, 0)).
        dt: sample period (for display and for estimators that need it).
        state_names, state_units, measurement_names: labels (default ``x0, x1, ...``, ``-``,
            ``z0, ...``).
        jacobians: optional analytic ``(F(x, u), H(x, u))`` with ``x`` (B, n).
        batch_size: number of runs the model is bound to.
    """

    def __init__(
        self,
        f: Callable[[np.ndarray, np.ndarray], np.ndarray],
        h: Callable[[np.ndarray, np.ndarray], np.ndarray],
        Q: np.ndarray,
        R: np.ndarray,
        nu: int = 0,
        dt: float = 1.0,
        state_names: tuple[str, ...] | None = None,
        state_units: tuple[str, ...] | None = None,
        measurement_names: tuple[str, ...] | None = None,
        jacobians: tuple[Callable, Callable] | None = None,
        batch_size: int = 1,
        name: str = "functional",
    ) -> None:
        self._f, self._h = f, h
        self.Q = np.asarray(Q, dtype=float)
        self.R = np.asarray(R, dtype=float)
        self.n, self.m, self.nu, self.dt = self.Q.shape[0], self.R.shape[0], nu, dt
        self.state_names = state_names or tuple(f"x{i}" for i in range(self.n))
        self.state_units = state_units or ("-",) * self.n
        self.measurement_names = measurement_names or tuple(f"z{i}" for i in range(self.m))
        self._jacobians = jacobians
        self.batch_size = batch_size
        self.name = name

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self._f(x, u)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self._h(x, u)

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        return None if self._jacobians is None else self._jacobians[0](x, u)

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray | None:
        return None if self._jacobians is None else self._jacobians[1](x, u)


class LinearGaussianModel(FilterModel):
    """``x⁺ = A x + Bu u + v``, ``z = C x + n`` with analytic Jacobians ``A`` and ``C``."""

    def __init__(
        self,
        A: np.ndarray,
        C: np.ndarray,
        Q: np.ndarray,
        R: np.ndarray,
        Bu: np.ndarray | None = None,
        dt: float = 1.0,
        batch_size: int = 1,
        state_names: tuple[str, ...] | None = None,
        state_units: tuple[str, ...] | None = None,
        measurement_names: tuple[str, ...] | None = None,
    ) -> None:
        self.A, self.C = np.asarray(A, dtype=float), np.asarray(C, dtype=float)
        self.Bu = np.zeros((self.A.shape[0], 0)) if Bu is None else np.asarray(Bu, dtype=float)
        self.Q, self.R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
        self.n, self.m, self.nu, self.dt = self.A.shape[0], self.C.shape[0], self.Bu.shape[1], dt
        self.state_names = state_names or tuple(f"x{i}" for i in range(self.n))
        self.state_units = state_units or ("-",) * self.n
        self.measurement_names = measurement_names or tuple(f"z{i}" for i in range(self.m))
        self.batch_size = batch_size
        self.name = "linear"

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return x @ self.A.T + (u @ self.Bu.T)[:, None, :]

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return x @ self.C.T

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.A, (x.shape[0], *self.A.shape)).copy()

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.C, (x.shape[0], *self.C.shape)).copy()

    def F_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.A, (*x.shape[:2], *self.A.shape)).copy()

    def H_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.C, (*x.shape[:2], *self.C.shape)).copy()
