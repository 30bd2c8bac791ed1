"""``quadest.conformance.check_sigma_point_moments``: the closed-form UT and Gaussian moments of a
quadratic, the real sigma-point filters pass, and a UKF with one classic bug each is refused.

``PlainUKF`` is a covariance-form UKF written here from the textbook (Julier & Uhlmann 2004),
sharing no code with quadest's filters; each subclass re-introduces one bug that a linear model
cannot see.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product
from typing import ClassVar

import numpy as np
import pytest

from quadest.conformance import Quadratic, check_estimator, check_sigma_point_moments, quadratic_moments
from quadest.estimators.base import Estimator
from quadest.estimators.cubature import CKF
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.registry import builtin_estimators
from quadest.estimators.srukf import SRUKF

UT_GRID = [{"alpha": a, "beta": b, "kappa": k} for a, b, k in product((1e-3, 0.5, 1.0), (0.0, 2.0), (0.0, 1.0))]

# which closed form each built-in sigma-point filter must reproduce
REFERENCE = {
    "ckf": {"ut": (1.0, 0.0, 0.0)},
    "srckf": {"ut": (1.0, 0.0, 0.0)},
    "cdkf": {"reference": "central_difference"},
    "srcdkf": {"reference": "central_difference"},
    "ckf5": {"reference": "gaussian"},
    "srckf5": {"reference": "gaussian"},
    "ghkf": {"reference": "gaussian"},
}


def registered(name: str) -> type:
    """The class registered as ``name``; a missing one fails here rather than skipping, which
    would pass the suite without checking it."""
    specs = builtin_estimators()
    assert name in specs, f"{name!r} has reference moments here but is not registered; registered: {sorted(specs)}"
    return specs[name].cls


@dataclass
class PlainUKFParams:
    kind: str = "plain_ukf"
    alpha: float = 0.5
    beta: float = 2.0
    kappa: float = 0.0


class PlainUKF(Estimator):
    """Covariance-form UKF, sigma points redrawn before the update."""

    Params = PlainUKFParams
    capabilities: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, model, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0) -> None:
        super().__init__(model)
        n = model.n
        lam = alpha**2 * (n + kappa) - n
        self.gamma = np.sqrt(n + lam)
        self.wm = np.full(2 * n + 1, 0.5 / (n + lam))
        self.wm[0] = lam / (n + lam)
        self.wc = self.wm.copy()
        self.wc[0] = self.zeroth_covariance_weight(lam / (n + lam), alpha, beta)

    def zeroth_covariance_weight(self, wm0: float, alpha: float, beta: float) -> float:
        return wm0 + 1.0 - alpha**2 + beta

    def initialize(self, x0, P0):
        self.x, self.P = np.array(x0, dtype=float), np.array(P0, dtype=float)
        self._reset_failures(self.x.shape[0])

    def _points(self):
        cols = self.gamma * np.swapaxes(np.linalg.cholesky(self.P), -1, -2)
        return np.concatenate([self.x[:, None], self.x[:, None] + cols, self.x[:, None] - cols], axis=1)

    def _moments(self, Y):
        mean = np.einsum("k,bkj->bj", self.wm, Y)
        d = Y - mean[:, None]
        return mean, np.einsum("k,bki,bkj->bij", self.wc, d, d)

    def predict(self, u):
        self.x, P = self._moments(self.model.f(self._points(), u))
        self.P = P + self.model.Q

    def update(self, z, u):
        X = self._points()
        Y = self.model.h(X, u)
        y, Pyy = self._moments(Y)
        Pyy = Pyy + self.model.R
        Pxy = np.einsum("k,bki,bkj->bij", self.wc, X - self.x[:, None], Y - y[:, None])
        K = np.swapaxes(np.linalg.solve(Pyy, np.swapaxes(Pxy, -1, -2)), -1, -2)
        self.x = self.x + np.einsum("bij,bj->bi", K, z - y)
        self.P = self.P - K @ Pyy @ np.swapaxes(K, -1, -2)

    @property
    def mean(self):
        return self.x

    @property
    def covariance(self):
        return self.P


class CovarianceWeightFromMeanWeight(PlainUKF):
    """W0(c) = W0(m): the 1 − α² + β term forgotten."""

    def zeroth_covariance_weight(self, wm0, alpha, beta):
        return wm0


class IgnoresBeta(PlainUKF):
    """β never reaches the weights."""

    def zeroth_covariance_weight(self, wm0, alpha, beta):
        return wm0 + 1.0 - alpha**2


class FlippedZerothWeight(PlainUKF):
    """The sign of W0(c) lost (|W0(c)| used, as a square-root filter that updates where it must
    downdate would)."""

    def zeroth_covariance_weight(self, wm0, alpha, beta):
        return abs(wm0 + 1.0 - alpha**2 + beta)


def test_closed_forms_match_a_large_sample_and_each_other():
    """The references are not taken on trust: (1) the UT formula equals the exact Gaussian
    moments where the UT is known to be exact for a scalar quadratic (n = 1, α = 1, β = 0,
    κ = 2: γ² = 3 matches the Gaussian fourth moment); (2) the Gaussian moments of an n = 4
    quadratic agree with 400 000 samples within 5 standard errors of the sample moments."""
    scalar = Quadratic(np.array([0.3]), np.array([[0.7]]), np.array([[[0.9]]]))
    mu1, var1 = np.array([[0.4]]), np.array([0.5])
    ut = quadratic_moments(scalar, mu1, var1, "ut", (1.0, 0.0, 2.0))
    exact = quadratic_moments(scalar, mu1, var1, "gaussian")
    for a, b in zip(ut, exact, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-14)

    rng = np.random.default_rng(0)
    poly = Quadratic(rng.standard_normal(2), rng.standard_normal((2, 4)), rng.standard_normal((2, 4, 4)))
    mu, var = np.array([[0.3, -0.5, 0.8, 0.1]]), np.array([0.2, 0.5, 0.3, 0.4])
    mean, cov, cross = quadratic_moments(poly, mu, var, "gaussian")
    N = 400_000
    d = rng.standard_normal((N, 4)) * np.sqrt(var)
    y = poly((mu + d)[None])[0]
    dy = y - y.mean(0)
    sample_cov = dy.T @ dy / (N - 1)
    se_mean = np.sqrt(np.diag(sample_cov) / N)
    assert (np.abs(y.mean(0) - mean[0]) <= 5 * se_mean).all()
    prods = dy[:, :, None] * dy[:, None, :]
    assert (np.abs(sample_cov - cov[0]) <= 5 * prods.std(0) / np.sqrt(N)).all()
    xy = d[:, :, None] * dy[:, None, :]
    assert (np.abs(xy.mean(0) - cross[0]) <= 5 * xy.std(0) / np.sqrt(N)).all()


@pytest.mark.parametrize("params", UT_GRID, ids=lambda p: "a{alpha}-b{beta}-k{kappa}".format(**p))
@pytest.mark.parametrize("cls", [SRUKF, FilterpyUKF, PlainUKF], ids=lambda c: c.__name__)
def test_ut_filters_have_the_closed_form_moments(cls, params):
    check_sigma_point_moments(cls, params)


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_other_sigma_point_filters_have_their_rules_moments(name):
    check_sigma_point_moments(registered(name), **REFERENCE[name])


@pytest.mark.parametrize("h", [1.0, 3.0])
def test_central_difference_filters_follow_their_step(h):
    for name in ("cdkf", "srcdkf"):
        check_sigma_point_moments(registered(name), {"h": h}, reference="central_difference")


def test_ckf_is_the_ut_with_alpha_one_beta_zero_kappa_zero_not_an_exact_rule():
    check_sigma_point_moments(CKF, ut=(1.0, 0.0, 0.0))
    with pytest.raises(AssertionError, match="exact Gaussian"):
        check_sigma_point_moments(CKF, reference="gaussian")


@pytest.mark.parametrize(
    ("bug", "params"),
    [
        (CovarianceWeightFromMeanWeight, {"alpha": 0.5, "beta": 2.0, "kappa": 0.0}),
        (CovarianceWeightFromMeanWeight, {"alpha": 1.0, "beta": 2.0, "kappa": 1.0}),
        (IgnoresBeta, {"alpha": 0.5, "beta": 2.0, "kappa": 0.0}),
        (FlippedZerothWeight, {"alpha": 0.5, "beta": 2.0, "kappa": 0.0}),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else "a{alpha}-b{beta}-k{kappa}".format(**v),
)
def test_nonlinear_check_refuses_a_ukf_with_a_classic_bug(bug, params):
    """Each bug passes the linear-Gaussian conformance (the W0 term vanishes there) and is
    refused by the quadratic probe."""
    check_estimator(bug, params=params)
    with pytest.raises(AssertionError, match="differs from the UT"):
        check_sigma_point_moments(bug, params)


def test_nonlinear_check_refuses_an_unknown_reference_and_missing_parameters():
    with pytest.raises(ValueError, match="reference must be one of"):
        check_sigma_point_moments(SRUKF, reference="degree3")
    with pytest.raises(ValueError, match="pass ut="):
        check_sigma_point_moments(CKF)
    with pytest.raises(ValueError, match="must be called h"):
        check_sigma_point_moments(CKF, reference="central_difference")
