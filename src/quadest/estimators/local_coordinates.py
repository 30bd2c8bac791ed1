"""A state that is not a vector (a quaternion, an INS state) seen by a vector filter: the filter's
state is the error ``δ`` about a reference point, ``x = origin ⊞ δ``.

This is how filterpy's vector EKF and UKF run on ``model=attitude`` and ``model=ins`` unchanged:
the filter carries ``δ`` (``n_err`` components) and its covariance; after each update the mean
error is moved into the reference and ``δ`` is reset to zero (the multiplicative EKF of Lefferts,
Markley & Shuster 1982; the unscented form is USQUE, Crassidis & Markley 2003, §III; Solà 2017,
"Quaternion kinematics for the error-state Kalman filter", §7.2). The reset Jacobian is taken as
the identity (Markley's convention; ``mekf`` with ``reset_jacobian: false`` is the same filter).

Time update of a sigma point ``δᵢ``: ``eᵢ = f(origin ⊞ δᵢ, u) ⊟ f(origin, u)``; the reference
moves to ``f(origin, u)`` and the filter's mean is the weighted mean of the ``eᵢ``, kept until
the update. Measurement functions see ``h(origin ⊞ δᵢ, u)``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from quadest.models.base import FilterModel


class LocalCoordinates:
    """The reference point of one run and the model's functions in the error coordinates about it.

    Points are arrays ``(..., n_err)``; ``origin`` is ``(n,)``.
    """

    def __init__(self, model: FilterModel) -> None:
        self.model = model
        self.origin = np.full(model.n, np.nan)
        self._target = self.origin

    def _at(self, d: np.ndarray) -> np.ndarray:
        """``origin ⊞ d`` for points of any leading shape."""
        return self.model.boxplus(np.broadcast_to(self.origin, (*d.shape[:-1], self.model.n)), d)

    def reset(self, x: np.ndarray) -> None:
        """Start at the state ``x`` (n,) with zero error."""
        self.origin = np.array(x, dtype=float)
        self._target = self.origin

    def advance(self, u: np.ndarray) -> None:
        """Before a time update: the reference of the predicted errors becomes ``f(origin, u)``."""
        self._target = self.model.f(self.origin[None, None, :], u[None, :])[0, 0]

    def f(self, d: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``f(origin ⊞ d, u) ⊟ f(origin, u)`` for points ``d`` (1, P, n_err), ``u`` (1, m_u)."""
        return self.model.boxminus(self.model.f(self._at(d), u), self._target)

    def settle(self) -> None:
        """After a time update: the predicted errors are about the new reference."""
        self.origin = self._target

    def measurement(self, h: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Callable:
        """The measurement function ``h`` at ``origin ⊞ d``."""
        return lambda d, u: h(self._at(d), u)

    def inject(self, d: np.ndarray) -> np.ndarray:
        """Move the error ``d`` (n_err,) into the reference; returns the zero error that replaces it."""
        self.origin = self.model.boxplus(self.origin[None], d[None])[0]
        self._target = self.origin
        return np.zeros_like(d)

    def state(self, d: np.ndarray) -> np.ndarray:
        """The state ``origin ⊞ d`` (n,) of an error ``d`` (n_err,)."""
        return self._at(np.asarray(d)[None])[0]
