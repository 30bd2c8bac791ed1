"""Integration rules: exact Gaussian moments up to each rule's degree, for dimensions 1 to 15.

The reference is independent of the rules: E[ξ^a] under N(0, I) is Π_k (a_k − 1)!! for even a_k
and 0 otherwise. A rule of degree d must reproduce every monomial of total degree ≤ d to
round-off (relative 1e-12 of the moment's scale: the weights are O(1) and the points O(√n)).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from quadest.numerics.rules import (
    CentralDifferenceRule,
    CubatureRule,
    FifthDegreeCubatureRule,
    GaussHermiteRule,
    UnscentedRule,
    rule_mean,
)


def gaussian_moment(powers: tuple[int, ...]) -> float:
    """E[Π ξ_k^a_k] for ξ ~ N(0, I): the product of double factorials (a − 1)!! of even powers."""
    out = 1.0
    for a in powers:
        if a % 2:
            return 0.0
        out *= float(np.prod(np.arange(a - 1, 0, -2))) if a else 1.0
    return out


def monomials(n: int, degree: int):
    """Exponent tuples of every monomial of total degree 1..degree in n variables."""
    for d in range(1, degree + 1):
        for combo in itertools.combinations_with_replacement(range(n), d):
            yield tuple(np.bincount(combo, minlength=n))


def worst_moment_error(rule, n: int, degree: int) -> float:
    """Largest error of the mean weights over all monomials up to ``degree`` (also degree 0:
    the weights must sum to one)."""
    xi = rule.unit_points(n)
    w = rule.mean_weights(n)
    worst = abs(w.sum() - 1.0)
    for a in monomials(n, degree):
        approx = float(w @ np.prod(xi ** np.array(a), axis=1))
        exact = gaussian_moment(a)
        worst = max(worst, abs(approx - exact) / max(1.0, exact))
    return worst


THIRD_DEGREE = [
    ("ut-0.5", UnscentedRule(0.5, 2.0, 0.0)),
    ("ut-1e-3", UnscentedRule(1e-3, 2.0, 0.0)),
    ("ut-kappa1", UnscentedRule(1.0, 0.0, 1.0)),
    ("cd", CentralDifferenceRule()),
    ("cubature3", CubatureRule()),
]


@pytest.mark.parametrize("n", range(1, 16))
@pytest.mark.parametrize("name,rule", THIRD_DEGREE, ids=[t[0] for t in THIRD_DEGREE])
def test_third_degree_rules_integrate_cubics_exactly(name, rule, n):
    # The UT's mean weight W0 is -1e6 at alpha = 1e-3 (n = 6): the sum loses ~|W0| eps.
    tol = 1e-12 * max(1.0, np.abs(rule.weights(n)[0]).max())
    assert worst_moment_error(rule, n, 3) <= tol


@pytest.mark.parametrize("n", range(1, 16))
@pytest.mark.slow
def test_fifth_degree_cubature_integrates_quintics_exactly(n):
    rule = FifthDegreeCubatureRule()
    assert len(rule.unit_points(n)) == 2 * n * n + 1
    assert worst_moment_error(rule, n, 5) <= 1e-12


@pytest.mark.parametrize("n", range(1, 16))
def test_fifth_degree_cubature_is_not_seventh_degree(n):
    """The rule must stop at degree 5 (E[ξ1^6] = 15 is missed): a sanity check that the moment
    test can fail."""
    rule = FifthDegreeCubatureRule()
    xi, w = rule.unit_points(n), rule.weights(n)[0]
    assert abs(w @ xi[:, 0] ** 6 - 15.0) > 1e-3


@pytest.mark.parametrize("n", range(1, 9))
@pytest.mark.slow
def test_gauss_hermite_p3_integrates_quintics_exactly(n):
    """Tensor product: p^n points, so dimensions stop at 8 here (6561 points); the rule is a
    product of 1-D rules, so exactness per coordinate carries to every dimension."""
    assert worst_moment_error(GaussHermiteRule(3), n, 5) <= 1e-12


def test_gauss_hermite_p10_is_exact_to_degree_19_in_one_dimension():
    """Each moment E[ξ^d], d ≤ 19, against its exact value, the error measured against the size of
    the summands Σ|w ξ^d|: an odd moment's exact zero is the cancellation of terms up to 1e7
    (the outer nodes ±4.86 to the 19th power), so its round-off is that size times eps, which an
    absolute tolerance would either miss or pass by luck of numpy's node bits. The bound is the
    dot product's p·eps (Higham 2002, §3.1) times d for the powers of each node's rounding."""
    rule, p, degree = GaussHermiteRule(10), 10, 19
    xi, w = rule.unit_points(1)[:, 0], rule.mean_weights(1)
    for d in range(degree + 1):
        terms = w * xi**d
        exact = gaussian_moment((d,))
        assert abs(terms.sum() - exact) <= (d + 1) * p * np.finfo(float).eps * max(1.0, np.abs(terms).sum()), d


def test_third_degree_rules_miss_fourth_moments():
    """E[ξ1^4] = 3: the cubature rule gives n (so only n = 3 is right); the test above would
    notice a rule claiming more than it has."""
    for n in (1, 2, 4, 6):
        xi, w = CubatureRule().unit_points(n), CubatureRule().weights(n)[0]
        assert np.isclose(w @ xi[:, 0] ** 4, n)


@pytest.mark.parametrize("n", [1, 4, 5, 9, 15])
def test_fifth_degree_weights_match_jia_xin_cheng(n):
    """Centre 2/(n+2), axis (4−n)/(2(n+2)²) (negative for n > 4), pairs 1/(n+2)²."""
    w = FifthDegreeCubatureRule().weights(n)[0]
    assert np.isclose(w[0], 2 / (n + 2))
    assert np.allclose(w[1 : 2 * n + 1], (4 - n) / (2 * (n + 2) ** 2))
    assert np.allclose(w[2 * n + 1 :], 1 / (n + 2) ** 2)
    assert (w[1 : 2 * n + 1] < 0).all() == (n > 4)


def test_unscented_offsets_equal_unit_points_times_factor():
    rng = np.random.default_rng(0)
    S = np.linalg.cholesky(np.cov(rng.standard_normal((5, 20))))[None]
    for rule in (UnscentedRule(0.3, 2.0, 1.0), CentralDifferenceRule(2.0), CubatureRule()):
        assert np.allclose(rule.offsets(S)[0], rule.unit_points(5) @ S[0].T, rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    "rule", [UnscentedRule(0.5, 2, 0), CentralDifferenceRule(), CubatureRule(), FifthDegreeCubatureRule()]
)
def test_square_root_columns_reproduce_the_covariance(rule):
    """``A Aᵀ + Σ sign c cᵀ`` (what the square-root filter factorises) equals the rule's covariance."""
    rng = np.random.default_rng(3)
    n, m = 6, 3
    Y = rng.standard_normal((2, len(rule.unit_points(n)), m))
    D = Y - rule_mean(Y, rule.mean_weights(n))[:, None, :]
    A = rule.sqrt_columns(D, n)
    P = A @ np.swapaxes(A, -1, -2)
    for cols, sign in rule.rank_one_terms(D, n):
        P = P + sign * cols @ np.swapaxes(cols, -1, -2)
    assert np.allclose(P, rule.covariance(D, n), rtol=1e-13, atol=1e-13)


def test_central_difference_covariance_is_the_divided_difference_formula():
    """Nørgaard et al. 2000: P = Σ_i [(Y_i − Y_{i+n})/(2h)]² + (h²−1)/(4h⁴) [Y_i + Y_{i+n} − 2Y_0]²,
    written out for a scalar output without the rule's helpers."""
    rng = np.random.default_rng(4)
    n, h = 3, 1.5
    Y = rng.standard_normal((1, 2 * n + 1, 1))
    rule = CentralDifferenceRule(h)
    y = Y[0, :, 0]
    expected = sum(
        ((y[i] - y[i + n]) / (2 * h)) ** 2 + (h * h - 1) / (4 * h**4) * (y[i] + y[i + n] - 2 * y[0]) ** 2
        for i in range(1, n + 1)
    )
    D = Y - rule_mean(Y, rule.mean_weights(n))[:, None, :]
    assert np.isclose(rule.covariance(D, n)[0, 0, 0], expected, rtol=1e-14)


def test_rules_refuse_parameters_without_real_points():
    with pytest.raises(ValueError, match="alpha"):
        UnscentedRule(-1.0).validate(3)
    with pytest.raises(ValueError, match="h must be"):
        CentralDifferenceRule(0.5).validate(3)
    with pytest.raises(ValueError, match="points exceed"):
        GaussHermiteRule(3).validate(15)
