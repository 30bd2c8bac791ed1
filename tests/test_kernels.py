"""The compiled square-root kernels (:mod:`quadest.numerics.compiled`) against their numpy
references (:mod:`quadest.numerics.square_root`), and the switch between them.

Tolerances, per run, from the backward stability of each algorithm (Higham, *Accuracy and Stability
of Numerical Algorithms*, 2nd ed.): two backward-stable computations of the same quantity differ by
at most twice the forward-error bound of one of them, ``(condition number) × (backward error)``.

- QR (Householder in the kernel, LAPACK's in the reference): backward error ``≲ n L eps ‖A‖``
  (Thm 19.4); the triangular factor's sensitivity is ``κ₂(A)``, so ``|ΔS| ≤ 2 n L eps κ₂(A) ‖A‖₂``.
- Gain ``K Pyy = Pxy`` by two triangular solves (Thm 8.5 for each): ``|ΔK| ≤ 4 m eps κ₂(Pyy) ‖K‖₂``.
- Whitening, one triangular solve: ``|Δy| ≤ 2 m eps κ₂(S) ‖y‖₂``.
- cholupdate: the kernel performs the reference's IEEE operations in the same order (numba contracts
  nothing to FMA without ``fastmath``), so the results must be identical: tolerance 0, which also
  catches a reordering that a round-off tolerance would let through.

A wrong sign, a skipped pivot or a transposed factor all give differences of order ``‖S‖``.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest

import quadest.numerics
from helpers import compose_settings, random_spd, run_filter, simulate, smooth_model
from quadest.app.validate import validate_run
from quadest.errors import ConfigError, DowndateError
from quadest.estimators.srukf import SRUKF
from quadest.numerics import compiled, square_root
from quadest.numerics.rules import UnscentedRule
from quadest.numerics.square_root import (
    cholupdate,
    cholupdate_numpy,
    kalman_gain,
    kalman_gain_numpy,
    kernel_backend,
    qr_factor,
    qr_factor_numpy,
    whiten,
    whiten_numpy,
)

EPS = np.finfo(float).eps


@pytest.fixture(autouse=True)
def _numba_backend(monkeypatch):
    """Every test starts on the compiled backend unless it switches."""
    monkeypatch.setenv("QUADEST_KERNELS", "numba")


def ill_conditioned(rng: np.random.Generator, B: int, n: int, L: int, decades: float) -> np.ndarray:
    """(B, n, L) matrices with singular values spread over ``decades`` decades (random rotations)."""
    out = np.empty((B, n, L))
    for b in range(B):
        U = np.linalg.qr(rng.standard_normal((n, n)))[0]
        V = np.linalg.qr(rng.standard_normal((L, L)))[0][:n]
        out[b] = (U * np.logspace(0.0, -decades, n)) @ V * rng.uniform(0.1, 10.0)
    return out


def lower_factors(rng: np.random.Generator, B: int, n: int, decades: float) -> np.ndarray:
    """Lower factors with a positive diagonal and condition number about ``10**decades``."""
    return qr_factor_numpy(ill_conditioned(rng, B, n, n, decades))


def ut_problem(rng: np.random.Generator, B: int, n: int, alpha: float):
    """What the SR-UKF's time update factorises at ``alpha`` (eqs 5.15–5.19): the QR columns
    ``√W1 (Y_i − ȳ)`` with ``√Q``, and the W0 column with its sign (a downdate when W0(c) < 0)."""
    rule = UnscentedRule(alpha, 2.0, 0.0)
    S = lower_factors(rng, B, n, 3.0)
    X = rule.offsets(S) + rng.standard_normal((B, 1, n))
    Y = X + 0.1 * np.sin(X) ** 2  # a smooth nonlinear map
    D = Y - np.einsum("i,bij->bj", rule.mean_weights(n), Y)[:, None]
    A = np.concatenate([rule.sqrt_columns(D, n), np.broadcast_to(0.1 * np.eye(n), (B, n, n))], axis=-1)
    [(cols, sign)] = rule.rank_one_terms(D, n)
    return A, cols, sign


def qr_tolerance(A: np.ndarray) -> np.ndarray:
    n, L = A.shape[-2:]
    return 2 * n * L * EPS * np.linalg.cond(A) * np.linalg.norm(A, 2, axis=(-2, -1))


def per_run_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a - b).reshape(a.shape[0], -1).max(axis=1)


# --- QR of the stacked factors (eqs 5.18, 5.23) ---


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize(("n", "extra"), [(1, 0), (1, 3), (3, 0), (4, 5), (6, 12), (7, 7)])
@pytest.mark.parametrize("decades", [0.0, 4.0, 8.0])
def test_qr_kernel_agrees_with_numpy(seed, n, extra, decades):
    rng = np.random.default_rng(seed)
    A = ill_conditioned(rng, 5, n, n + extra, decades)
    out, ref = qr_factor(A), qr_factor_numpy(A)
    assert (per_run_error(out, ref) <= qr_tolerance(A)).all()
    assert (np.diagonal(out, axis1=-2, axis2=-1) > 0).all()
    np.testing.assert_array_equal(np.triu(out, 1), 0.0)


@pytest.mark.parametrize("alpha", [1e-3, 0.5])
@pytest.mark.parametrize("n", [2, 6, 9])
def test_qr_kernel_agrees_on_sigma_point_columns(alpha, n):
    A, _, _ = ut_problem(np.random.default_rng(n), 20, n, alpha)
    assert (per_run_error(qr_factor(A), qr_factor_numpy(A)) <= qr_tolerance(A)).all()


def test_qr_kernel_of_a_zero_row_and_leading_axes():
    """A row of zeros (an unexcited state) gives a zero pivot, like LAPACK, and the factor still
    reproduces ``A Aᵀ`` to its backward error ``n L eps ‖A‖²`` (which needs no condition number);
    any leading axes work."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((2, 3, 4, 7))
    A[0, 1, 2] = 0.0
    out, ref = qr_factor(A), qr_factor_numpy(A)
    assert out.shape == ref.shape == (2, 3, 4, 4)
    assert out[0, 1, 2, 2] == ref[0, 1, 2, 2] == 0.0
    gram_error = np.abs(out @ np.swapaxes(out, -1, -2) - A @ np.swapaxes(A, -1, -2)).max(axis=(-2, -1))
    assert (gram_error <= 2 * 4 * 7 * EPS * np.linalg.norm(A, 2, axis=(-2, -1)) ** 2).all()
    full = np.ones((2, 3), dtype=bool)
    full[0, 1] = False
    assert (per_run_error(out[full], ref[full]) <= qr_tolerance(A[full])).all()


# --- cholupdate (eqs 5.19, 5.24, 5.29) ---


def both_cholupdates(S, u, nu):
    """The kernel's and the reference's outcome: ``(factor, failed runs)`` each."""
    outcomes = []
    for fun in (cholupdate, cholupdate_numpy):
        try:
            outcomes.append((fun(S, u, nu), []))
        except DowndateError as err:
            outcomes.append((err.result, err.runs.tolist()))
    return outcomes


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("n", [1, 3, 6])
@pytest.mark.parametrize("k", [1, 4])
@pytest.mark.parametrize("nu", [0.7, -1.0])
@pytest.mark.parametrize("decades", [0.0, 6.0])
def test_cholupdate_kernel_is_the_reference_bit_for_bit(seed, n, k, nu, decades):
    rng = np.random.default_rng(seed)
    B = 8
    S = lower_factors(rng, B, n, decades)
    W = rng.standard_normal((B, n, k))
    W *= rng.uniform(0.0, 1.3, (B, 1, 1)) / np.linalg.norm(W, 2, axis=(1, 2), keepdims=True)
    U = S @ W  # ‖W‖₂ > 1 in some runs: those downdates fail
    (out, failed), (ref, ref_failed) = both_cholupdates(S, U, nu)
    assert failed == ref_failed
    np.testing.assert_array_equal(out, ref)
    np.testing.assert_array_equal(out[failed], S[failed])


@pytest.mark.parametrize("n", [3, 6])
def test_cholupdate_kernel_agrees_on_the_small_alpha_downdate(n):
    """α = 1e-3: W0(c) ≈ −1e6 makes the time update's W0 term a downdate (eq. 5.19)."""
    A, cols, sign = ut_problem(np.random.default_rng(10 + n), 50, n, 1e-3)
    assert sign == -1.0
    S = qr_factor_numpy(A)
    (out, failed), (ref, ref_failed) = both_cholupdates(S, cols, sign)
    assert failed == ref_failed
    np.testing.assert_array_equal(out, ref)


def test_cholupdate_kernel_flags_what_the_reference_flags():
    """A failing downdate, a NaN factor and a NaN vector each fail their own run only; the result
    keeps those runs' input factors, and the other runs are those of the runs alone."""
    rng = np.random.default_rng(4)
    S = lower_factors(rng, 6, 4, 2.0)
    u = 0.3 * np.einsum("bij,bj->bi", S, rng.standard_normal((6, 4)) / 4)
    u[1] = 2.0 * S[1, :, 0]  # S Sᵀ − u uᵀ indefinite
    S[3, 2, 1] = np.nan
    u[4, 0] = np.nan
    (out, failed), (ref, ref_failed) = both_cholupdates(S, u, -1.0)
    assert failed == ref_failed == [1, 3, 4]
    np.testing.assert_array_equal(out, ref)
    for run in (0, 2, 5):
        np.testing.assert_array_equal(out[run], cholupdate(S[run : run + 1], u[run : run + 1], -1.0)[0])


def test_cholupdate_kernel_leaves_its_inputs_alone():
    rng = np.random.default_rng(8)
    S = lower_factors(rng, 3, 4, 1.0)
    u = rng.standard_normal((3, 4, 2))
    S0, u0 = S.copy(), u.copy()
    cholupdate(S, u, 0.5)
    np.testing.assert_array_equal(S, S0)
    np.testing.assert_array_equal(u, u0)


# --- the gain (eq. 5.26) and whitening ---


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize(("n", "m"), [(6, 6), (6, 3), (9, 2), (4, 1)])
@pytest.mark.parametrize("decades", [0.0, 3.0, 6.0])
def test_gain_kernel_agrees_with_numpy(seed, n, m, decades):
    """Partially observed: the states with a zero row of ``Pxy`` get a zero gain in both."""
    rng = np.random.default_rng(seed)
    B = 10
    Sy = lower_factors(rng, B, m, decades)
    Pxy = rng.standard_normal((B, n, m))
    Pxy[:, 1] = 0.0
    K, ref = kalman_gain(Pxy, Sy), kalman_gain_numpy(Pxy, Sy)
    Pyy = Sy @ np.swapaxes(Sy, -1, -2)
    tol = 4 * m * EPS * np.linalg.cond(Pyy) * np.linalg.norm(ref, 2, axis=(-2, -1))
    assert (per_run_error(K, ref) <= tol).all()
    np.testing.assert_array_equal(K[:, 1], 0.0)


@pytest.mark.parametrize("decades", [0.0, 6.0])
def test_whiten_kernel_agrees_with_numpy(decades):
    rng = np.random.default_rng(6)
    S = lower_factors(rng, 20, 6, decades)
    r = rng.standard_normal((20, 6))
    y, ref = whiten(S, r), whiten_numpy(S, r)
    tol = 2 * 6 * EPS * np.linalg.cond(S) * np.linalg.norm(ref, axis=-1)
    assert (per_run_error(y, ref) <= tol).all()


# --- NaN runs and "a batch equals each run alone" ---


def test_a_nan_run_poisons_no_other_run():
    rng = np.random.default_rng(9)
    A, cols, sign = ut_problem(rng, 6, 5, 0.5)
    A[2, 3, 4] = np.nan
    S, S_ref = qr_factor(A), qr_factor_numpy(A)
    finite = np.isfinite(S).all(axis=(1, 2))
    np.testing.assert_array_equal(finite, np.isfinite(S_ref).all(axis=(1, 2)))
    assert finite.tolist() == [True, True, False, True, True, True]
    (_, failed), (_, ref_failed) = both_cholupdates(S, cols, sign)
    assert failed == ref_failed == [2]
    Pxy, Sy = rng.standard_normal((6, 5, 5)), S.copy()
    K = kalman_gain(Pxy, Sy)
    assert np.isfinite(K).all(axis=(1, 2)).tolist() == finite.tolist()


def test_each_kernel_gives_a_batch_what_it_gives_each_run_alone():
    rng = np.random.default_rng(12)
    A, cols, _ = ut_problem(rng, 7, 6, 0.5)
    S = qr_factor(A)
    U = 0.1 * S @ rng.standard_normal((7, 6, 6)) / 6
    Pxy, r = rng.standard_normal((7, 9, 6)), rng.standard_normal((7, 6))
    batched = (S, cholupdate(S, cols, 1.0), cholupdate(S, U, -1.0), kalman_gain(Pxy, S), whiten(S, r))
    for i in range(7):
        one = slice(i, i + 1)
        alone = (
            qr_factor(A[one]),
            cholupdate(S[one], cols[one], 1.0),
            cholupdate(S[one], U[one], -1.0),
            kalman_gain(Pxy[one], S[one]),
            whiten(S[one], r[one]),
        )
        for b, a in zip(batched, alone, strict=True):
            np.testing.assert_array_equal(b[i], a[0])


# --- the SR-UKF's fused steps (quadest.numerics.unscented, eqs 5.15–5.29) ---
#
# The kernels sum the means and Pxy in another order than numpy's matmul, factorise with the
# Householder LQ instead of LAPACK and apply the same rank-one rotations: every difference is
# round-off, propagated through the factorisations. The tolerance is measured on each problem, not
# guessed: ten times how far the reference itself moves, at most over three draws, when its inputs
# are rounded differently (each entry multiplied by 1 + 2 eps ξ, ξ ~ N(0, 1)), plus 64 eps of the
# result's magnitude for
# the runs whose reference barely moves (the test_srukf_identities.py yardstick, per run). A wrong
# weight, a swapped index or a dropped term all give differences of the order of the result.


def unscented_problem(rng: np.random.Generator, B: int, n: int, m: int, alpha: float, decades: float):
    """Points ``X`` about ``x`` with factor ``S`` (condition ≈ 10**decades), their images ``Y``
    under a smooth map to m outputs, the noise factor (m, m) and a measurement ``z``."""
    from quadest.numerics.unscented import unscented_points_numpy

    rule = UnscentedRule(alpha, 2.0, 0.0)
    S = lower_factors(rng, B, n, decades)
    x = rng.standard_normal((B, n))
    X = unscented_points_numpy(x, S, rule.ut(n).gamma)
    M = rng.standard_normal((n, m))
    Y = X @ M + 0.1 * np.sin(X @ M) ** 2
    sqrt_noise = np.linalg.cholesky(random_spd(rng, m, 0.1))
    return rule.ut(n), x, S, X, Y, sqrt_noise, rng.standard_normal((B, m))


def rounded(rng: np.random.Generator, a: np.ndarray) -> np.ndarray:
    return a * (1.0 + 2.0 * EPS * rng.standard_normal(a.shape))


def measured_tolerance(reference, args: tuple, perturb: tuple[int, ...], outputs: tuple[int, ...]) -> list:
    """Per output (and per run): 10 × the reference's move under rounded inputs + 64 eps |output|."""
    rng = np.random.default_rng(99)
    base = reference(*args)
    moves = [reference(*(rounded(rng, a) if i in perturb else a for i, a in enumerate(args))) for _ in range(3)]
    return [
        10.0 * np.max([per_run_error(moved[k], base[k]) for moved in moves], axis=0)
        + 64 * EPS * np.abs(base[k]).reshape(len(base[k]), -1).max(1)
        for k in outputs
    ]


def test_unscented_points_kernel_is_the_reference_bit_for_bit():
    from quadest.numerics.unscented import unscented_points, unscented_points_numpy

    ut, x, S, _, _, _, _ = unscented_problem(np.random.default_rng(20), 9, 6, 6, 0.5, 4.0)
    np.testing.assert_array_equal(unscented_points(x, S, ut.gamma), unscented_points_numpy(x, S, ut.gamma))


@pytest.mark.parametrize("alpha", [1e-3, 0.5, 1.0])
@pytest.mark.parametrize(("n", "m"), [(6, 6), (6, 3), (4, 1), (9, 2)])
@pytest.mark.parametrize("decades", [0.0, 4.0])
def test_unscented_moments_kernel_agrees_with_numpy(alpha, n, m, decades):
    """Mean and factor of transformed points with additive noise (eqs 5.17–5.19, 5.22–5.24),
    partially observed (m < n) and at α = 1e-3, where W0(c) ≈ −1e6 makes the rank-one term a
    downdate that fails in some runs: both must fail the same runs and keep the same factor."""
    from quadest.numerics.unscented import unscented_moments, unscented_moments_numpy

    ut, _, _, _, Y, sqrt_noise, _ = unscented_problem(np.random.default_rng(n + m), 12, n, m, alpha, decades)
    mean, S, failed = unscented_moments(Y, ut, sqrt_noise)
    ref_mean, ref_S, ref_failed = unscented_moments_numpy(Y, ut, sqrt_noise)
    np.testing.assert_array_equal(failed, ref_failed)
    tol_mean, tol_S = measured_tolerance(unscented_moments_numpy, (Y, ut, sqrt_noise), (0,), (0, 1))
    assert (per_run_error(mean, ref_mean) <= tol_mean).all()
    assert (per_run_error(S, ref_S) <= tol_S).all()
    np.testing.assert_array_equal(np.triu(S, 1), 0.0)


@pytest.mark.parametrize("alpha", [1e-3, 0.5])
@pytest.mark.parametrize(("n", "m"), [(6, 6), (6, 3), (4, 1)])
@pytest.mark.parametrize("decades", [0.0, 3.0])
def test_unscented_correction_kernel_agrees_with_numpy(alpha, n, m, decades):
    """``Pxy``, gain, corrected mean and posterior downdate (eqs 5.25–5.29); the prior factor of
    two runs is shrunk so that their downdate by ``K Sy`` fails in both implementations."""
    from quadest.numerics.unscented import unscented_correction, unscented_correction_numpy, unscented_moments_numpy

    ut, x, S, X, Y, sqrt_noise, z = unscented_problem(np.random.default_rng(30 + n), 12, n, m, alpha, decades)
    y_mean, Sy, _ = unscented_moments_numpy(Y, ut, sqrt_noise)
    S = S.copy()
    S[[3, 7]] *= 0.05
    args = (X, x, Y, y_mean, ut.wc, Sy, S, z)
    out, ref = unscented_correction(*args), unscented_correction_numpy(*args)
    np.testing.assert_array_equal(out[3], ref[3])
    assert ref[3][[3, 7]].all()
    tols = measured_tolerance(unscented_correction_numpy, args, (0, 2, 5), (0, 1, 2))
    for k, tol in zip((0, 1, 2), tols, strict=True):
        assert (per_run_error(out[k], ref[k]) <= tol).all(), k


def test_unscented_kernels_keep_a_nan_run_in_its_row_and_give_a_batch_each_run_alone():
    from quadest.numerics.unscented import unscented_correction, unscented_moments, unscented_points

    ut, x, S, _, _, sqrt_noise, z = unscented_problem(np.random.default_rng(40), 7, 6, 3, 0.5, 2.0)
    x = x.copy()
    x[2, 4] = np.nan

    def step(x, S, z):
        X = unscented_points(x, S, ut.gamma)
        Y = X[..., :3] + 0.1 * np.sin(X[..., 3:]) ** 2
        y_mean, Sy, failed_y = unscented_moments(Y, ut, sqrt_noise)
        return (X, y_mean, Sy, failed_y, *unscented_correction(X, x, Y, y_mean, ut.wc, Sy, S, z))

    batched = step(x, S, z)
    assert batched[3].tolist() == [False, False, True, False, False, False, False]
    assert batched[-1].tolist() == batched[3].tolist()
    for i in range(7):
        one = slice(i, i + 1)
        for b, a in zip(batched, step(x[one], S[one], z[one]), strict=True):
            np.testing.assert_array_equal(b[i], a[0])


# --- the filter on both backends ---


@pytest.mark.parametrize("alpha", [1e-3, 0.5])
def test_srukf_on_both_backends_equals_the_covariance_ukf(monkeypatch, alpha):
    """The SR-UKF on either backend against filterpy's covariance UKF, with the tolerance of the
    identity tests (tests/test_srukf_identities.py: 1e-9, or ten times this problem's measured
    round-off floor), and the two backends against each other with the same tolerance."""
    from test_srukf_identities import compare_srukf_filterpy, relative, tolerances

    n = 4
    model = smooth_model(2, n=n, m=2)
    rng = np.random.default_rng(102)
    P0 = random_spd(rng, n, 0.5)[None]
    x_true, u, z = simulate(model, rng.standard_normal((1, n)), 120, 2)
    x0 = x_true[:, 0] + rng.standard_normal((1, n)) @ np.linalg.cholesky(P0[0]).T
    tol_x, tol_P = tolerances(model, x0, P0, u, z, alpha, 2.0, 0.0)
    runs = {}
    for backend in ("numba", "numpy"):
        monkeypatch.setenv("QUADEST_KERNELS", backend)
        assert kernel_backend() == backend
        for (xs, Ps), (xf, Pf) in compare_srukf_filterpy(model, x0, P0, u, z, alpha, 2.0, 0.0):
            assert xs.shape[0] >= 100
            assert relative(xs, xf) <= tol_x
            assert relative(Ps, Pf) <= tol_P
        runs[backend] = run_filter(SRUKF(model, alpha, 2.0, 0.0), model, x0, P0, u, z)
    assert relative(runs["numba"][0], runs["numpy"][0]) <= tol_x
    assert relative(runs["numba"][1], runs["numpy"][1]) <= tol_P


# --- the switch ---


def test_the_switch_selects_the_backend(monkeypatch):
    calls = []
    monkeypatch.setattr(compiled, "cholupdate_kernel", lambda *args: calls.append("kernel"))
    S = lower_factors(np.random.default_rng(0), 2, 3, 0.0)
    u = np.ones((2, 3))
    cholupdate(S, u, 1.0)
    assert calls == ["kernel"]
    monkeypatch.setenv("QUADEST_KERNELS", "numpy")
    assert kernel_backend() == "numpy"
    cholupdate(S, u, 1.0)
    assert calls == ["kernel"]
    monkeypatch.delenv("QUADEST_KERNELS")
    assert kernel_backend() == "numba"


def test_without_numba_the_numpy_path_runs(monkeypatch):
    monkeypatch.setitem(sys.modules, "numba", None)
    monkeypatch.setitem(sys.modules, "quadest.numerics.compiled", None)
    monkeypatch.delattr(quadest.numerics, "compiled")
    square_root._compiled.cache_clear()
    try:
        assert kernel_backend() == "numpy"
        A = np.random.default_rng(1).standard_normal((2, 3, 5))
        np.testing.assert_array_equal(qr_factor(A), qr_factor_numpy(A))
    finally:
        square_root._compiled.cache_clear()


def test_a_bad_backend_is_a_one_line_config_error(monkeypatch):
    monkeypatch.setenv("QUADEST_KERNELS", "jax")
    with pytest.raises(ConfigError, match=r"^QUADEST_KERNELS='jax' is invalid: allowed values are numba, numpy$"):
        kernel_backend()

    from quadest.app.schema import ExperimentConf

    with pytest.raises(ConfigError, match="QUADEST_KERNELS"):
        validate_run(ExperimentConf())  # every other field at its valid default


# --- the quadrotor model's compiled f and h ---


@pytest.fixture(scope="module", params=["thesis", "augmented"])
def quadrotor(request):
    from quadest.simulation.quadrotor_data import build_quadrotor_data

    return build_quadrotor_data(compose_settings([f"model.formulation={request.param}", "runs=4", "duration=0.2"]))


def quadrotor_points(data, seed: int = 0):
    """Sigma-point-like clouds (B, 13, n) about the initial states, with components of both signs
    (the asymmetry term acts with the sign), and the filter inputs (B, nu) with spread angles."""
    model, rng = data.model, np.random.default_rng(seed)
    x = data.x0[:, None, :] + 0.5 * rng.standard_normal((data.x0.shape[0], 13, model.n))
    u = model.filter_input(data.inputs[:, 0], data.companion_truth[:, 0])
    if model.thesis:
        u[:, 4:7] += 0.3 * rng.standard_normal((u.shape[0], 3))
    return x, u


@pytest.mark.parametrize("calibrated", [True, False])
def test_quadrotor_f_and_h_kernels_agree_with_numpy(quadrotor, calibrated):
    """Each output is the reference's expression term by term; what may differ is libm's sine and
    cosine against numpy's (about an ulp each) and the order of the three-term triad products, so
    the difference is a few eps times the magnitudes involved: 32 eps (|x| + |out|) per run."""
    from quadest.sensors.mimu import TriadErrors

    model = quadrotor.model
    if not calibrated:
        model = model.select(slice(None))
        model.accel_errors = model.gyro_errors = TriadErrors.nominal(model.batch_size)
    x, u = quadrotor_points(quadrotor)
    for name in ("f", "h"):
        out, ref = getattr(model, name)(x, u), getattr(model, f"{name}_numpy")(x, u)
        tol = 32 * EPS * (np.abs(x).max(axis=(1, 2)) + np.abs(ref).max(axis=(1, 2)))
        assert (per_run_error(out, ref) <= tol).all(), name


def test_quadrotor_kernels_run_on_the_numba_backend_only(quadrotor, monkeypatch):
    """The compiled f/h are used for real points of the model's runs; complex steps (the Jacobians),
    other shapes and ``QUADEST_KERNELS=numpy`` take the numpy reference."""
    from quadest.models import quadrotor_kernels

    calls = []
    real_f = quadrotor_kernels.quadrotor_f
    monkeypatch.setattr(quadrotor_kernels, "quadrotor_f", lambda *a: calls.append("f") or real_f(*a))
    model = quadrotor.model
    x, u = quadrotor_points(quadrotor)
    model.f(x, u)
    assert calls == ["f"]
    F = model.F_analytic(x[:, 0], u)
    model.f(x[:2], u[:2])
    assert calls == ["f"]
    monkeypatch.setenv("QUADEST_KERNELS", "numpy")
    model.f(x, u)
    assert calls == ["f"]
    np.testing.assert_array_equal(model.F_analytic(x[:, 0], u), F)


def test_a_nan_point_of_the_quadrotor_model_stays_in_its_point(quadrotor):
    model = quadrotor.model
    x, u = quadrotor_points(quadrotor)
    x[1, 5, 0] = np.nan
    for name in ("f", "h"):
        out = getattr(model, name)(x, u)
        bad = ~np.isfinite(out).all(axis=-1)
        np.testing.assert_array_equal(bad, ~np.isfinite(getattr(model, f"{name}_numpy")(x, u)).all(axis=-1))
        assert bad.sum() == 1 and bad[1, 5]


WARM_UP_SCRIPT = """
import os
import json, sys
import numpy as np
from quadest.estimators.srukf import SRUKF
from quadest.models.functional import LinearGaussianModel
SRUKF(LinearGaussianModel(np.eye(2), np.eye(2), np.eye(2), np.eye(2), dt=0.1), 0.5)
compiled = sys.modules.get("quadest.numerics.compiled")
names = ("qr_factor_kernel", "cholupdate_kernel", "kalman_gain_kernel", "whiten_kernel")
print(json.dumps([name for name in names if compiled is not None and getattr(compiled, name).signatures]))
"""


@pytest.mark.parametrize(("backend", "loaded"), [("numba", 4), ("numpy", 0)])
@pytest.mark.integration
def test_building_an_estimator_loads_the_kernels_before_any_timed_step(backend, loaded):
    """numba's first call in a process initialises its compiler (tenths of a second); the runner
    times ``initialize`` and the steps, so the kernels are loaded when the estimator is built."""
    import subprocess

    env = {**os.environ, "QUADEST_KERNELS": backend}
    out = subprocess.run([sys.executable, "-c", WARM_UP_SCRIPT], env=env, capture_output=True, text=True, check=True)
    assert len(json.loads(out.stdout)) == loaded


def test_building_an_estimator_loads_the_models_compiled_f_and_h(quadrotor, monkeypatch):
    from quadest.models import quadrotor_kernels

    calls = []
    for name in ("quadrotor_f", "quadrotor_h"):
        monkeypatch.setattr(quadrotor_kernels, name, lambda *a, name=name: calls.append(name))
    SRUKF(quadrotor.model, 0.5)
    assert calls == ["quadrotor_f", "quadrotor_h"]
