"""Shared square-root numerics against independent references (numpy Cholesky, filterpy's
sigma points), as hypothesis property tests over random well-conditioned cases. Every test runs
on both backends of the square-root numerics (``QUADEST_KERNELS``: the compiled kernels and the
numpy references)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints
from hypothesis import given, settings
from hypothesis import strategies as st

from quadest.errors import DowndateError, FilterDivergence
from quadest.numerics import cholupdate, kalman_gain, qr_factor, ut_weights, whiten
from quadest.numerics.rules import UnscentedRule, rule_mean

PROPERTY = settings(max_examples=1000, deadline=None)


@pytest.fixture(scope="module", autouse=True, params=["numba", "numpy"])
def kernels(request):
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("QUADEST_KERNELS", request.param)
        yield request.param


cases = st.tuples(st.integers(0, 2**32 - 1), st.sampled_from([1, 4]), st.integers(1, 7))


def random_factor(rng: np.random.Generator, B: int, n: int) -> np.ndarray:
    """Lower factors of well-conditioned SPD matrices (eigenvalues within about 1e-1..1e1)."""
    A = rng.standard_normal((B, n, n))
    P = A @ np.swapaxes(A, -1, -2) / n + 0.5 * np.eye(n)
    return np.linalg.cholesky(P)


def gram(S: np.ndarray) -> np.ndarray:
    return S @ np.swapaxes(S, -1, -2)


@pytest.mark.slow
@PROPERTY
@given(cases)
def test_cholupdate_update_matches_fresh_cholesky(case):
    seed, B, n = case
    rng = np.random.default_rng(seed)
    S = random_factor(rng, B, n)
    v = rng.standard_normal((B, n))
    nu = rng.uniform(0.1, 3.0)
    out = cholupdate(S, v, nu)
    ref = np.linalg.cholesky(gram(S) + nu * v[:, :, None] * v[:, None, :])
    np.testing.assert_allclose(out, ref, rtol=1e-9, atol=1e-11)
    assert np.allclose(np.triu(out, 1), 0.0)


@pytest.mark.slow
@PROPERTY
@given(cases)
def test_cholupdate_downdate_matches_fresh_cholesky(case):
    seed, B, n = case
    rng = np.random.default_rng(seed)
    S = random_factor(rng, B, n)
    # v = S w with |w| < 1 keeps S Sᵀ − v vᵀ = S (I − w wᵀ) Sᵀ positive definite.
    w = rng.standard_normal((B, n))
    w *= rng.uniform(0.0, 0.9, (B, 1)) / np.linalg.norm(w, axis=-1, keepdims=True)
    v = np.einsum("bij,bj->bi", S, w)
    out = cholupdate(S, v, -1.0)
    ref = np.linalg.cholesky(gram(S) - v[:, :, None] * v[:, None, :])
    np.testing.assert_allclose(out, ref, rtol=1e-8, atol=1e-10)


@pytest.mark.slow
@PROPERTY
@given(cases)
def test_sequential_matrix_downdate_matches_fresh_cholesky(case):
    seed, B, n = case
    rng = np.random.default_rng(seed)
    S = random_factor(rng, B, n)
    k = 3
    W = rng.standard_normal((B, n, k))
    W *= 0.5 / np.linalg.norm(W, axis=(1, 2), keepdims=True)  # ‖W‖₂ < 1: S(I − WWᵀ)Sᵀ is PD
    U = S @ W
    out = cholupdate(S, U, -1.0)
    np.testing.assert_allclose(out, np.linalg.cholesky(gram(S) - gram(U)), rtol=1e-8, atol=1e-10)


@pytest.mark.slow
@PROPERTY
@given(cases, st.integers(0, 6))
def test_qr_factor_matches_cholesky_of_gram(case, extra):
    seed, B, n = case
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((B, n, n + extra))
    out = qr_factor(A)
    # The reference chol(A Aᵀ) loses about cond(A)² eps (a square random A can be badly conditioned);
    # QR itself is backward stable, so that is the yardstick.
    tol = max(1e-9, 10 * np.finfo(float).eps * np.linalg.cond(A).max() ** 2)
    scale = np.abs(out).max()
    np.testing.assert_allclose(out, np.linalg.cholesky(gram(A)), rtol=tol, atol=tol * scale)
    assert (np.diagonal(out, axis1=-2, axis2=-1) > 0).all()


def test_downdate_that_loses_definiteness_raises_with_failed_runs():
    rng = np.random.default_rng(1)
    S = random_factor(rng, 3, 4)
    v = np.zeros((3, 4))
    v[1] = 2.0 * S[1, :, 0] / 0.999  # run 1: S Sᵀ − v vᵀ is indefinite
    with pytest.raises(DowndateError) as info:
        cholupdate(S, v, -1.0)
    err = info.value
    assert isinstance(err, FilterDivergence)
    assert err.runs.tolist() == [1]
    assert np.isfinite(err.result).all()
    for ok in (0, 2):  # the other runs are still right
        np.testing.assert_allclose(err.result[ok], S[ok], rtol=1e-12)


def test_kalman_gain_equals_inverse_form():
    rng = np.random.default_rng(2)
    Sy = random_factor(rng, 5, 3)
    Pxy = rng.standard_normal((5, 6, 3))
    expected = Pxy @ np.linalg.inv(gram(Sy))
    np.testing.assert_allclose(kalman_gain(Pxy, Sy), expected, rtol=1e-10, atol=1e-12)


def test_whiten_gives_mahalanobis_distance():
    rng = np.random.default_rng(3)
    S = random_factor(rng, 4, 5)
    r = rng.standard_normal((4, 5))
    expected = np.einsum("bi,bij,bj->b", r, np.linalg.inv(gram(S)), r)
    np.testing.assert_allclose(np.sum(whiten(S, r) ** 2, axis=-1), expected, rtol=1e-10)


@pytest.mark.parametrize("alpha", [1e-3, 0.5, 1.0])
@pytest.mark.parametrize("beta", [0.0, 2.0])
@pytest.mark.parametrize("kappa", [0.0, -3.0])
def test_weights_and_points_match_filterpy(alpha, beta, kappa):
    n = 6
    w = ut_weights(n, alpha, beta, kappa)
    ref = MerweScaledSigmaPoints(n, alpha=alpha, beta=beta, kappa=kappa)
    np.testing.assert_allclose(w.wm, ref.Wm, rtol=1e-14)
    np.testing.assert_allclose(w.wc, ref.Wc, rtol=1e-14)
    rng = np.random.default_rng(4)
    S = random_factor(rng, 1, n)
    x = rng.standard_normal((1, n))
    points = x[:, None, :] + UnscentedRule(alpha, beta, kappa).offsets(S)
    np.testing.assert_allclose(points[0], ref.sigma_points(x[0], gram(S)[0]), rtol=1e-12)


def test_negative_center_weight_at_small_alpha():
    """W0(c) ≈ −1e6 at α = 1e-3, n = 6 (thesis eqs 5.2–5.9; docs/sources.md)."""
    w = ut_weights(6, 1e-3, 2.0, 0.0)
    assert -1.0e6 * 1.01 < w.wc[0] < -1.0e6 * 0.99
    assert np.isclose(w.wm.sum(), 1.0)


@pytest.mark.parametrize(("alpha", "kappa"), [(0.0, 0.0), (-1.0, 0.0), (1.0, -6.0), (0.5, -7.0)])
def test_invalid_scaling_is_rejected(alpha, kappa):
    with pytest.raises(ValueError, match="must be > 0"):
        ut_weights(6, alpha, 2.0, kappa)


def test_unscented_rule_is_exact_for_linear_maps():
    rng = np.random.default_rng(5)
    n = 4
    S = random_factor(rng, 2, n)
    x = rng.standard_normal((2, n))
    M = rng.standard_normal((3, n))
    for alpha in (1e-3, 1.0):
        rule = UnscentedRule(alpha, 2.0, 0.0)
        Y = (x[:, None, :] + rule.offsets(S)) @ M.T
        mean = rule_mean(Y, rule.mean_weights(n))
        cov = rule.covariance(Y - mean[:, None, :], n)
        np.testing.assert_allclose(mean, x @ M.T, rtol=1e-6 if alpha < 0.1 else 1e-12, atol=1e-8)
        np.testing.assert_allclose(cov, M @ gram(S) @ M.T, rtol=1e-6, atol=1e-8)


def test_weighted_mean_keeps_digits_the_direct_sum_loses():
    """At α = 1e-3 the direct sum Σ Wi Yi cancels terms of size 1e6 |Y|; the deviation form
    does not. The exact mean of points placed symmetrically around c is c."""
    w = ut_weights(6, 1e-3, 2.0, 0.0)
    c = np.full(3, 12345.678)
    d = np.random.default_rng(6).standard_normal((6, 3)) * 1e-3
    Y = np.concatenate([c[None], c + d, c - d])[None]
    assert np.abs(rule_mean(Y, w.wm)[0] - c).max() < 1e-11
    assert np.abs(np.einsum("i,bij->bj", w.wm, Y)[0] - c).max() > 1e-9


def test_cholupdate_leaves_its_inputs_alone():
    rng = np.random.default_rng(8)
    for B, n in ((1, 1), (1, 3), (3, 1), (3, 4)):
        S = random_factor(rng, B, n)
        v = rng.standard_normal((B, n))
        S0, v0 = S.copy(), v.copy()
        cholupdate(S, v, 0.5)
        np.testing.assert_array_equal(S, S0)
        np.testing.assert_array_equal(v, v0)


def test_cholupdate_of_an_empty_factor_is_empty():
    """A model without a primary measurement (``model=ins``) has a 0 × 0 innovation factor."""
    out = cholupdate(np.zeros((3, 0, 0)), np.zeros((3, 0, 2)), -1.0)
    assert out.shape == (3, 0, 0)


def _linearized_problem(seed: int, B: int = 3, n: int = 4, m: int = 2):
    """Random SPD ``P`` (B, n, n), ``R`` (m, m), a Jacobian ``H`` (B, m, n) and the optimal gain."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((B, n, n))
    P = A @ np.swapaxes(A, -1, -2) / n + 0.3 * np.eye(n)
    C = rng.standard_normal((m, m))
    R = C @ C.T / m + 0.2 * np.eye(m)
    H = rng.standard_normal((B, m, n))
    S = H @ P @ np.swapaxes(H, -1, -2) + R
    K_opt = np.linalg.solve(S, H @ P).swapaxes(-1, -2)  # P Hᵀ S⁻¹ (S symmetric)
    return rng, P, H, R, S, K_opt


def test_joseph_covariance_matches_filterpy_update():
    """filterpy's ``KalmanFilter.update`` (Joseph form) run by run is the independent reference;
    the two differ by round-off only."""
    from filterpy.kalman import KalmanFilter

    from quadest.numerics.joseph import joseph_covariance

    _, P, H, R, _, K_opt = _linearized_problem(11)
    out = joseph_covariance(P, H, R, K_opt)
    for b in range(P.shape[0]):
        kf = KalmanFilter(dim_x=P.shape[-1], dim_z=R.shape[0])
        kf.P, kf.H, kf.R = P[b].copy(), H[b], R
        kf.update(np.zeros(R.shape[0]))
        np.testing.assert_allclose(out[b], kf.P, rtol=1e-12, atol=1e-14)


def test_joseph_covariance_of_any_gain_is_the_optimum_plus_the_gain_error_term():
    """For every gain, ``(I − K H) P (I − K H)ᵀ + K R Kᵀ = P_opt + (K − K*) S (K − K*)ᵀ`` with
    ``K* = P Hᵀ S⁻¹`` (complete the square): the identity the short form ``(I − K H) P`` fails
    off the optimum. Tolerance: round-off of O(1) matrices."""
    from quadest.numerics.joseph import joseph_covariance

    rng, P, H, R, S, K_opt = _linearized_problem(12)
    P_opt = P - K_opt @ S @ np.swapaxes(K_opt, -1, -2)
    dK = 0.5 * rng.standard_normal(K_opt.shape)
    expected = P_opt + dK @ S @ np.swapaxes(dK, -1, -2)
    np.testing.assert_allclose(joseph_covariance(P, H, R, K_opt + dK), expected, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(joseph_covariance(P, H, R, K_opt), P_opt, rtol=1e-11, atol=1e-12)
