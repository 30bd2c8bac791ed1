"""Integration rules of the sigma-point family: how a Gaussian N(x̂, S Sᵀ) is replaced by points.

A rule answers four questions for a sigma-point filter (dynamax's ``GHKFIntegrals`` pattern: the
filter is one, the rule is swappable):

1. **points**: ``offsets(S)`` (B, L, n), added to the mean (``x̂ ⊞ offset``);
2. **mean**: the weights ``wm`` (L,), applied as ``Y0 + Σ wm_i (Y_i − Y0)`` (:func:`rule_mean`);
3. **square-root covariance**: ``sqrt_columns(D)`` (B, m, c), the columns whose QR is the factor,
   plus ``rank_one_terms(D)``, the (columns, sign) pairs applied afterwards by ``cholupdate``
   (the UT's centre point, the negative weights of the fifth-degree rule). ``D`` holds the
   deviations ``Y_i − ȳ`` (B, L, m). The covariance form uses the same columns
   (:meth:`IntegrationRule.covariance`);
4. **cross-covariance** ``Pxy`` from state and measurement deviations.

Central differences fit the same mould: their covariance comes from divided differences of the
points, not from weights, so they override the columns and the cross-covariance, and they give a
posterior factor without a downdate (:meth:`IntegrationRule.posterior_columns`).

Rules:

- :class:`UnscentedRule`: scaled symmetric UT (thesis eqs 5.1–5.9; van der Merwe 2004).
- :class:`CentralDifferenceRule`: Nørgaard, Poulsen & Ravn 2000 (Automatica 36(11)); van der
  Merwe 2004 (OHSU thesis: the CDKF and the SR-CDKF).
- :class:`CubatureRule`: third-degree spherical–radial cubature, Arasaratnam & Haykin 2009
  (IEEE TAC 54(6)), eqs 36–38.
- :class:`FifthDegreeCubatureRule`: Jia, Xin & Cheng 2013 (Automatica 49(2)), 2n² + 1 points.
- :class:`GaussHermiteRule`: tensor-product Gauss–Hermite, p points per dimension (Ito & Xiong
  2000, IEEE TAC 45(5)).

All functions take a leading batch axis; weights depend only on the dimension and are cached.
"""

from __future__ import annotations

import itertools
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cache

import numpy as np

from quadest.numerics.sigma_points import UTWeights, ut_weights
from quadest.numerics.transpose import matrix_transpose as _t


def rule_mean(Y: np.ndarray, wm: np.ndarray) -> np.ndarray:
    """``Σ wm_i Y_i`` for ``Y`` (B, L, m) in the deviation form ``Y0 + Σ_{i≥1} wm_i (Y_i − Y0)``,
    which keeps the digits a direct sum loses when ``|wm_0|`` is large (UT at small α)."""
    Y0 = Y[..., 0, :]
    return Y0 + wm[1:] @ (Y[..., 1:, :] - Y0[..., None, :])


class IntegrationRule(ABC):
    """A rule for Gaussian expectations, for any dimension (weights computed per dimension).

    Subclasses give ``unit_points(n)`` and ``weights(n)``; the symmetric and divided-difference
    rules override the methods below where their structure is cheaper or different.
    """

    name: str = "rule"

    @abstractmethod
    def unit_points(self, n: int) -> np.ndarray:
        """Points ξ (L, n) for N(0, I)."""

    @abstractmethod
    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance weights ``(wm, wc)``, each (L,)."""

    def offsets(self, S: np.ndarray) -> np.ndarray:
        """Offsets ``S ξ_i`` of the points from the mean, (B, L, n), for a factor ``S`` (B, n, n)."""
        return self.unit_points(S.shape[-1]) @ _t(S)

    def mean_weights(self, n: int) -> np.ndarray:
        """The weights of the mean, (L,), for points of dimension ``n``."""
        return self.weights(n)[0]

    def sqrt_columns(self, D: np.ndarray, n: int) -> np.ndarray:
        """Columns ``√w_i D_i`` of the points with positive covariance weight, (B, m, c)."""
        wc = self.weights(n)[1]
        keep = wc > 0
        return _t(np.sqrt(wc[keep])[:, None] * D[..., keep, :])

    def rank_one_terms(self, D: np.ndarray, n: int) -> list[tuple[np.ndarray, float]]:
        """``(columns (B, m, k), sign)``: the negative-weight points, applied as one multi-column
        Cholesky downdate after the QR."""
        wc = self.weights(n)[1]
        neg = wc < 0
        if not neg.any():
            return []
        return [(_t(np.sqrt(-wc[neg])[:, None] * D[..., neg, :]), -1.0)]

    def covariance(self, D: np.ndarray, n: int) -> np.ndarray:
        """``Σ wc_i D_i D_iᵀ`` (B, m, m): the covariance-form twin of the square-root columns."""
        wc = self.weights(n)[1]
        return _t(wc[:, None] * D) @ D

    def cross_covariance(self, DX: np.ndarray, DY: np.ndarray, n: int) -> np.ndarray:
        """``Pxy = Σ wc_i DX_i DY_iᵀ`` (B, nx, m) from state and measurement deviations."""
        wc = self.weights(n)[1]
        return _t(wc[:, None] * DX) @ DY

    def posterior_columns(self, DX: np.ndarray, DY: np.ndarray, K: np.ndarray, n: int) -> np.ndarray | None:
        """Columns whose QR (with ``K √R``) is the posterior factor, or ``None``: then the square-root
        filter downdates ``S⁻`` by ``K Sy`` (thesis eqs 5.28–5.29)."""
        return None

    def validate(self, n: int) -> None:
        """Raise ``ValueError`` when the rule has no real points in dimension ``n``."""
        self.weights(n)


@dataclass(frozen=True)
class UnscentedRule(IntegrationRule):
    """Scaled symmetric unscented transform (thesis eqs 5.2–5.7; van der Merwe 2004).

    Points ``x̂, x̂ ± γ S_i`` with γ = √(n + λ). The square-root step is the thesis's: QR of
    ``√W1(c) (Y_1:2n − ȳ)`` then a rank-one ``cholupdate`` with ``Y_0 − ȳ`` by ``W0(c)``, a downdate
    when ``W0(c) < 0`` (eqs 5.18–5.19, 5.23–5.24). That downdate belongs to this rule only.
    """

    alpha: float = 0.5
    beta: float = 2.0
    kappa: float = 0.0
    name: str = "unscented"

    def ut(self, n: int) -> UTWeights:
        """Scaling and weights of the UT in dimension ``n`` (eqs 5.2–5.6), computed once."""
        return _cached_ut(n, self.alpha, self.beta, self.kappa)

    def unit_points(self, n: int) -> np.ndarray:
        g = self.ut(n).gamma
        return np.concatenate([np.zeros((1, n)), g * np.eye(n), -g * np.eye(n)])

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        w = self.ut(n)
        return w.wm, w.wc

    def offsets(self, S: np.ndarray) -> np.ndarray:
        """``[0, γ S, −γ S]`` (eqs 5.7, 5.15, 5.20): column ``i`` of ``S`` gives point ``i``."""
        cols = self.ut(S.shape[-1]).gamma * _t(S)
        return np.concatenate([np.zeros_like(cols[..., :1, :]), cols, -cols], axis=-2)

    def sqrt_columns(self, D: np.ndarray, n: int) -> np.ndarray:
        return np.sqrt(self.ut(n).wc[1]) * _t(D[..., 1:, :])

    def rank_one_terms(self, D: np.ndarray, n: int) -> list[tuple[np.ndarray, float]]:
        wc0 = self.ut(n).wc[0]
        return [(np.sqrt(abs(wc0)) * D[..., 0, :, None], 1.0 if wc0 >= 0 else -1.0)]


@cache
def _cached_ut(n: int, alpha: float, beta: float, kappa: float):
    return ut_weights(n, alpha, beta, kappa)


@dataclass(frozen=True)
class CentralDifferenceRule(IntegrationRule):
    """Central differences with step ``h`` (Nørgaard et al. 2000; van der Merwe 2004).

    Points ``x̂, x̂ ± h S_i``; mean weights ``W0 = (h² − n)/h²``, ``Wi = 1/(2h²)``. The covariance is
    built from first- and second-order divided differences, not from weights:
    ``A1 = (Y_1:n − Y_n+1:2n)/(2h)``, ``A2 = √(h² − 1)/(2h²) (Y_1:n + Y_n+1:2n − 2 Y_0)``,
    ``P = A1 A1ᵀ + A2 A2ᵀ``: every term is added, so the square-root form never downdates.
    ``Pxy = X1 Y1ᵀ`` from the first-order differences of the state points (``= S⁻ Y1ᵀ`` when the
    points are drawn from ``S⁻``). h² = 3 is optimal for a Gaussian prior.
    """

    h: float = float(np.sqrt(3.0))
    name: str = "central_difference"

    def validate(self, n: int) -> None:
        if not self.h >= 1.0:
            raise ValueError(f"h must be >= 1 (the second-order weight needs h^2 >= 1), got {self.h}")

    def unit_points(self, n: int) -> np.ndarray:
        return np.concatenate([np.zeros((1, n)), self.h * np.eye(n), -self.h * np.eye(n)])

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        h2 = self.h**2
        wm = np.full(2 * n + 1, 0.5 / h2)
        wm[0] = (h2 - n) / h2
        return wm, wm

    def offsets(self, S: np.ndarray) -> np.ndarray:
        cols = self.h * _t(S)
        return np.concatenate([np.zeros_like(cols[..., :1, :]), cols, -cols], axis=-2)

    def _first_order(self, D: np.ndarray, n: int) -> np.ndarray:
        return _t(D[..., 1 : n + 1, :] - D[..., n + 1 :, :]) / (2.0 * self.h)

    def _second_order(self, D: np.ndarray, n: int) -> np.ndarray:
        c = np.sqrt(self.h**2 - 1.0) / (2.0 * self.h**2)
        return c * _t(D[..., 1 : n + 1, :] + D[..., n + 1 :, :] - 2.0 * D[..., :1, :])

    def sqrt_columns(self, D: np.ndarray, n: int) -> np.ndarray:
        return np.concatenate([self._first_order(D, n), self._second_order(D, n)], axis=-1)

    def rank_one_terms(self, D: np.ndarray, n: int) -> list[tuple[np.ndarray, float]]:
        return []

    def covariance(self, D: np.ndarray, n: int) -> np.ndarray:
        A = self.sqrt_columns(D, n)
        return A @ _t(A)

    def cross_covariance(self, DX: np.ndarray, DY: np.ndarray, n: int) -> np.ndarray:
        return self._first_order(DX, n) @ _t(self._first_order(DY, n))

    def posterior_columns(self, DX: np.ndarray, DY: np.ndarray, K: np.ndarray, n: int) -> np.ndarray:
        """``[X1 − K Y1, X2, K Y2]`` (van der Merwe 2004, the SR-CDKF, with ``X1 = S⁻``, ``X2 = 0``
        for redrawn points): with ``K √R`` appended, its QR is the factor of ``P⁻ − K Pyy Kᵀ``."""
        X1, X2 = self._first_order(DX, n), self._second_order(DX, n)
        Y1, Y2 = self._first_order(DY, n), self._second_order(DY, n)
        return np.concatenate([X1 - K @ Y1, X2, K @ Y2], axis=-1)


@dataclass(frozen=True)
class CubatureRule(IntegrationRule):
    """Third-degree spherical–radial cubature (Arasaratnam & Haykin 2009, eqs 36–38): 2n points
    ``√n [I, −I]`` with weights ``1/(2n)``. Equals the UT with α = 1, β = 0, κ = 0."""

    name: str = "cubature3"

    def unit_points(self, n: int) -> np.ndarray:
        return np.sqrt(n) * np.concatenate([np.eye(n), -np.eye(n)])

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        w = np.full(2 * n, 0.5 / n)
        return w, w

    def offsets(self, S: np.ndarray) -> np.ndarray:
        cols = np.sqrt(S.shape[-1]) * _t(S)
        return np.concatenate([cols, -cols], axis=-2)


@dataclass(frozen=True)
class FifthDegreeCubatureRule(IntegrationRule):
    """Fifth-degree spherical–radial cubature (Jia, Xin & Cheng 2013, Automatica 49(2), eq. 41 with
    the radial rule of their §3): 2n² + 1 points for N(0, I): the centre with weight 2/(n+2),
    ``±√(n+2) e_i`` with weight (4 − n)/(2(n+2)²), ``±√(n+2) (e_k ± e_l)/√2`` (k < l) with weight
    1/(n+2)². The axis weights are negative for n > 4: the square-root filter then downdates with
    those 2n columns, and the covariance form can lose definiteness (its runs are flagged)."""

    name: str = "cubature5"

    def unit_points(self, n: int) -> np.ndarray:
        return _cubature5(n)[0]

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        w = _cubature5(n)[1]
        return w, w


@cache
def _cubature5(n: int) -> tuple[np.ndarray, np.ndarray]:
    r = np.sqrt(n + 2.0)
    eye = np.eye(n)
    pairs = [eye[k] + s * eye[l] for k, l in itertools.combinations(range(n), 2) for s in (1.0, -1.0)]
    pair_pts = r / np.sqrt(2.0) * np.array(pairs).reshape(-1, n)
    points = np.concatenate([np.zeros((1, n)), r * eye, -r * eye, pair_pts, -pair_pts])
    w = np.concatenate(
        [
            [2.0 / (n + 2.0)],
            np.full(2 * n, (4.0 - n) / (2.0 * (n + 2.0) ** 2)),
            np.full(2 * len(pair_pts), 1.0 / (n + 2.0) ** 2),
        ]
    )
    return points, w


@dataclass(frozen=True)
class GaussHermiteRule(IntegrationRule):
    """Tensor-product Gauss–Hermite rule with ``p`` points per dimension (Ito & Xiong 2000):
    ``p^n`` points, exact for polynomials of degree ≤ 2p − 1 in each coordinate. The 1-D nodes are
    the probabilists' Hermite roots (weight e^(−x²/2)), so no √2 rescaling is needed."""

    p: int = 3
    name: str = "gauss_hermite"
    max_points: int = 200_000

    def validate(self, n: int) -> None:
        if not (isinstance(self.p, int | np.integer) and self.p >= 1):
            raise ValueError(f"p must be an integer >= 1, got {self.p}")
        problem = self.size_problem(n)
        if problem is not None:
            raise ValueError(problem)

    def size_problem(self, n: int) -> str | None:
        """Why the grid is too large in dimension ``n`` (``p^n`` points over :attr:`max_points`), or None."""
        if self.p**n > self.max_points:
            return f"p^n = {self.p}^{n} points exceed {self.max_points}; lower p"
        return None

    def unit_points(self, n: int) -> np.ndarray:
        return _gauss_hermite(n, self.p)[0]

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        w = _gauss_hermite(n, self.p)[1]
        return w, w


@cache
def _gauss_hermite(n: int, p: int) -> tuple[np.ndarray, np.ndarray]:
    nodes, w1 = np.polynomial.hermite_e.hermegauss(p)
    w1 = w1 / np.sqrt(2.0 * np.pi)
    # Order the nodes so that the one nearest zero comes first: the mean's deviation form then
    # subtracts the centre point (exactly zero for odd p).
    order = np.argsort(np.abs(nodes), kind="stable")
    nodes, w1 = nodes[order], w1[order]
    grid = np.array(list(itertools.product(range(p), repeat=n)), dtype=int).reshape(-1, n)
    return nodes[grid], np.prod(w1[grid], axis=-1)
