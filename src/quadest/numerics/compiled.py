"""Compiled kernels (numba) for the square-root numerics of the SR-UKF (seed 000, §5.2.3).

Each kernel computes what its numpy reference in :mod:`quadest.numerics.square_root` computes,
to round-off, one Monte Carlo run after the other in a single serial loop over the batch, with
hand-written small-matrix arithmetic and scratch arrays allocated once per call (never per run):

- :func:`qr_factor_kernel` — ``qr{A}`` of eqs 5.18, 5.23 as a Householder LQ decomposition of
  each run's ``A`` (n × L): ``A = S Q`` with orthonormal rows ``Q``, so ``S Sᵀ = A Aᵀ``. The
  reference factorises ``Aᵀ`` with LAPACK instead; both give the unique factor with a positive
  diagonal.
- :func:`cholupdate_kernel` — ``cholupdate{S, u, ±ν}`` of eqs 5.19, 5.24, 5.29, the same rotations
  in the same order as the reference, with the failed runs marked and given back their input.
- :func:`kalman_gain_kernel` — eq. 5.26, ``K = (Pxy / Syᵀ) / Sy`` by forward then back substitution.
- :func:`whiten_kernel` — ``S⁻¹ r`` by forward substitution (NEES, NIS).

The callers are the public functions of :mod:`quadest.numerics.square_root`, which choose the
backend (``QUADEST_KERNELS``, docs/benchmarks.md) and check the shapes; the kernels expect
C-contiguous float64 arrays and write into ``out`` arrays given to them.

Threads: the QR and cholupdate kernels are a serial driver around a body for a range of runs
(``*_runs``), so that ``parallel=True`` with ``prange`` over chunks of runs can be measured with the
same body (``python benchmarks/bench_srukf.py``, docs/benchmarks.md). On the shared 2-core machine
it did not pay at these matrix sizes, so the kernels are serial. ``error_model="numpy"`` makes a
division by zero give inf/NaN (as in numpy) instead of raising, so a broken run stays in its row.
``cache=True`` keeps the machine code on disk (next to this file, or numba's user cache when that
directory is read-only); only the kernels a job calls are compiled.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_JIT = {"cache": True, "error_model": "numpy", "nogil": True}


@njit(**_JIT)
def qr_factor_kernel(A: np.ndarray, out: np.ndarray) -> None:
    """``out[b]`` for every run: see :func:`qr_factor_runs`."""
    _, n, L = A.shape
    qr_factor_runs(A, out, np.empty((n, L)), 0, A.shape[0])


@njit(**_JIT)
def qr_factor_runs(A: np.ndarray, out: np.ndarray, W: np.ndarray, first: int, stop: int) -> None:
    """``out[b]`` for runs ``first ≤ b < stop``: lower triangular with a positive diagonal and
    ``out[b] out[b]ᵀ = A[b] A[b]ᵀ`` (:func:`lq_factor` of a copy of ``A[b]``).

    ``A`` (B, n, L) with L ≥ n; ``W`` (n, L) is the scratch copy of one run.
    """
    _, n, L = A.shape
    for b in range(first, stop):
        for i in range(n):
            for j in range(L):
                W[i, j] = A[b, i, j]
        lq_factor(W, out[b])


@njit(**_JIT)
def lq_factor(W: np.ndarray, out: np.ndarray) -> None:
    """``out`` (n, n) lower triangular with a positive diagonal and ``out outᵀ = W Wᵀ`` for one
    run's ``W`` (n, L), L ≥ n, which is overwritten (the thesis's ``qr{·}``, eqs 5.18, 5.23).

    Row ``k`` of ``W`` is reflected onto ``e_k`` by the Householder vector ``v = x − α e_1`` with
    ``α = −sign(x_0) ‖x‖`` (no cancellation in ``v_0``), applied to the rows below;
    ``out[k, k] = |α|`` and column ``k`` of ``out`` is multiplied by ``sign(α)``, which leaves
    ``out outᵀ`` unchanged (the reference's sign fix).
    """
    n, L = W.shape
    for i in range(n):
        for j in range(n):
            out[i, j] = 0.0
    for k in range(n):
        sigma2 = 0.0
        for j in range(k, L):
            sigma2 += W[k, j] * W[k, j]
        sigma = math.sqrt(sigma2)
        if sigma == 0.0:  # the row is already zero from k on: nothing to reflect
            for i in range(k + 1, n):
                out[i, k] = W[i, k]
            continue
        x0 = W[k, k]
        alpha = -sigma if x0 >= 0.0 else sigma
        v0 = x0 - alpha
        W[k, k] = v0
        beta = 1.0 / (sigma * (sigma + abs(x0)))  # 2 / vᵀv
        sign = -1.0 if alpha < 0.0 else 1.0
        out[k, k] = sigma
        for i in range(k + 1, n):
            dot = 0.0
            for j in range(k, L):
                dot += W[i, j] * W[k, j]
            t = beta * dot
            for j in range(k, L):
                W[i, j] -= t * W[k, j]
            out[i, k] = sign * W[i, k]


@njit(**_JIT)
def cholupdate_kernel(
    S: np.ndarray, X: np.ndarray, scale: float, downdate: bool, out: np.ndarray, failed: np.ndarray
) -> None:
    """``out[b]`` and ``failed[b]`` for every run: see :func:`cholupdate_runs`."""
    cholupdate_runs(S, X, scale, downdate, out, failed, np.empty(S.shape[1]), 0, S.shape[0])


@njit(**_JIT)
def cholupdate_runs(
    S: np.ndarray,
    X: np.ndarray,
    scale: float,
    downdate: bool,
    out: np.ndarray,
    failed: np.ndarray,
    v: np.ndarray,
    first: int,
    stop: int,
) -> None:
    """``out[b]`` and ``failed[b]`` for runs ``first ≤ b < stop`` (:func:`cholupdate_run` of each);
    ``S`` (B, n, n), ``X`` (B, n, k), ``v`` (n,) the scratch column."""
    for b in range(first, stop):
        failed[b] = cholupdate_run(S[b], X[b], scale, downdate, out[b], v)


@njit(**_JIT)
def cholupdate_run(S: np.ndarray, X: np.ndarray, scale: float, downdate: bool, out: np.ndarray, v: np.ndarray) -> bool:
    """``out`` = the factor of ``S Sᵀ ± scale² Σ_j x_j x_jᵀ`` for the columns ``x_j`` of one run's
    ``X`` (n, k); returns whether the run failed.

    The arithmetic of each pivot is the reference's (eq. 5.29): ``r = √(L_kk² ± v_k²)``,
    ``c = r / L_kk``, ``s = v_k / L_kk``, ``col = (col ± s v) / c``, ``v = c v − s col``. A result
    with a non-positive or NaN diagonal or a non-finite entry (a failed downdate, or a NaN input)
    fails: ``out`` gets the input factor back. ``v`` (n,) is the scratch column.
    """
    n = S.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = S[i, j]
    for j in range(X.shape[1]):
        for i in range(n):
            v[i] = X[i, j] * scale
        for p in range(n):
            Lpp = out[p, p]
            vp = v[p]
            r2 = Lpp * Lpp
            v2 = vp * vp
            r = math.sqrt(r2 - v2) if downdate else math.sqrt(r2 + v2)
            c = r / Lpp
            s = vp / Lpp
            signed_s = -s if downdate else s
            out[p, p] = r
            for i in range(p + 1, n):
                col = (out[i, p] + signed_s * v[i]) / c
                out[i, p] = col
                v[i] = v[i] * c - s * col
    bad = False
    for i in range(n):
        if not out[i, i] > 0.0:
            bad = True
        for j in range(n):
            if not math.isfinite(out[i, j]):
                bad = True
    if bad:
        for i in range(n):
            for j in range(n):
                out[i, j] = S[i, j]
    return bad


@njit(**_JIT)
def kalman_gain_kernel(Pxy: np.ndarray, Sy: np.ndarray, K: np.ndarray) -> None:
    """``K[b]`` for every run: see :func:`kalman_gain_run`. ``Pxy`` (B, n, m), ``Sy`` (B, m, m)."""
    B, n, m = Pxy.shape
    Y = np.empty((n, m))
    for b in range(B):
        kalman_gain_run(Pxy[b], Sy[b], K[b], Y)


@njit(**_JIT)
def kalman_gain_run(Pxy: np.ndarray, Sy: np.ndarray, K: np.ndarray, Y: np.ndarray) -> None:
    """``K Sy Syᵀ = Pxy`` (eq. 5.26) for one run, every row ``i`` of ``K``: ``Sy y = Pxy[i]``
    forward, then ``Syᵀ K[i] = y`` backward. ``Pxy`` (n, m), ``Sy`` (m, m) lower triangular,
    ``Y`` (n, m) scratch.

    The rows are solved side by side (the loop over ``i`` innermost), so that their divisions are
    independent and overlap in the processor; each element is computed as in a row-by-row solve,
    ``y_r = (b_r − Σ_{c<r} Sy_rc y_c) / Sy_rr`` with the sum in increasing ``c``.
    """
    n, m = Pxy.shape
    for r in range(m):
        d = Sy[r, r]
        for i in range(n):
            acc = Pxy[i, r]
            for c in range(r):
                acc -= Sy[r, c] * Y[i, c]
            Y[i, r] = acc / d
    for r in range(m - 1, -1, -1):
        d = Sy[r, r]
        for i in range(n):
            acc = Y[i, r]
            for c in range(r + 1, m):
                acc -= Sy[c, r] * K[i, c]
            K[i, r] = acc / d


@njit(**_JIT)
def whiten_kernel(S: np.ndarray, r: np.ndarray, out: np.ndarray) -> None:
    """``out[b] = S[b]⁻¹ r[b]`` by forward substitution; ``S`` (B, m, m), ``r`` (B, m)."""
    B, m = r.shape
    for b in range(B):
        for i in range(m):
            acc = r[b, i]
            for c in range(i):
                acc -= S[b, i, c] * out[b, c]
            out[b, i] = acc / S[b, i, i]


# --- the SR-UKF's steps fused: one call per stage for the whole batch (quadest.numerics.unscented) ---


@njit(**_JIT)
def unscented_points_kernel(x: np.ndarray, S: np.ndarray, gamma: float, out: np.ndarray) -> None:
    """Sigma points ``out[b] = [x, x + γ S_i, x − γ S_i]`` (B, 2n+1, n) of means ``x`` (B, n) and
    factors ``S`` (B, n, n): point ``1 + i`` and ``1 + n + i`` from column ``i`` of ``S``."""
    B, n = x.shape
    for b in range(B):
        for j in range(n):
            out[b, 0, j] = x[b, j]
        for i in range(n):
            for j in range(n):
                c = gamma * S[b, j, i]
                out[b, 1 + i, j] = x[b, j] + c
                out[b, 1 + n + i, j] = x[b, j] + -c


@njit(**_JIT)
def unscented_moments_kernel(
    Y: np.ndarray,
    wm: np.ndarray,
    col_scale: float,
    w0_scale: float,
    w0_downdate: bool,
    sqrt_noise: np.ndarray,
    mean: np.ndarray,
    S: np.ndarray,
    failed: np.ndarray,
) -> None:
    """Mean (B, m) and factor (B, m, m) of transformed points ``Y`` (B, L, m) plus additive noise
    with factor ``sqrt_noise`` (m, q), one run at a time:

    ``mean = Y_0 + Σ_{i≥1} wm_i (Y_i − Y_0)`` (summed in increasing i); ``D_i = Y_i − mean``; the
    factor is :func:`lq_factor` of ``[col_scale D_1 … col_scale D_{L−1}, sqrt_noise]`` followed by
    :func:`cholupdate_run` with ``w0_scale D_0`` (a downdate when ``w0_downdate``). A run whose
    rank-one change fails gets ``failed[b] = True`` and the factor before it.
    """
    B, L, m = Y.shape
    q = sqrt_noise.shape[1]
    W = np.empty((m, L - 1 + q))
    F = np.empty((m, m))
    col = np.empty((m, 1))
    acc = np.empty(m)
    v = np.empty(m)
    for b in range(B):
        for j in range(m):
            acc[j] = 0.0
        for i in range(1, L):
            for j in range(m):
                acc[j] += wm[i] * (Y[b, i, j] - Y[b, 0, j])
        for j in range(m):
            mean[b, j] = Y[b, 0, j] + acc[j]
            col[j, 0] = w0_scale * (Y[b, 0, j] - mean[b, j])
        for j in range(m):
            for i in range(1, L):
                W[j, i - 1] = col_scale * (Y[b, i, j] - mean[b, j])
            for c in range(q):
                W[j, L - 1 + c] = sqrt_noise[j, c]
        lq_factor(W, F)
        failed[b] = cholupdate_run(F, col, 1.0, w0_downdate, S[b], v)


@njit(**_JIT)
def unscented_correction_kernel(
    X: np.ndarray,
    x: np.ndarray,
    Y: np.ndarray,
    y_mean: np.ndarray,
    wc: np.ndarray,
    Sy: np.ndarray,
    S: np.ndarray,
    z: np.ndarray,
    x_post: np.ndarray,
    S_post: np.ndarray,
    nu: np.ndarray,
    failed: np.ndarray,
) -> None:
    """The measurement correction, one run at a time: ``Pxy = Σ_i wc_i (X_i − x)(Y_i − ȳ)ᵀ``, the
    gain by :func:`kalman_gain_run`, ``ν = z − ȳ``, ``x_post = x + K ν`` and ``S_post`` the
    downdate of ``S`` by the columns of ``K Sy`` (:func:`cholupdate_run`; ``failed[b]`` and the
    prior factor for a run where it fails). ``X`` (B, L, n), ``Y`` (B, L, m). Every sum runs in
    increasing order of its index, with independent sums side by side in the innermost loop."""
    B, L, n = X.shape
    m = Y.shape[2]
    DX = np.empty(n)
    DY = np.empty(m)
    Pxy = np.empty((n, m))
    K = np.empty((n, m))
    Ys = np.empty((n, m))
    U = np.empty((n, m))
    corr = np.empty(n)
    v = np.empty(n)
    for b in range(B):
        for r in range(n):
            for c in range(m):
                Pxy[r, c] = 0.0
        for i in range(L):
            for r in range(n):
                DX[r] = wc[i] * (X[b, i, r] - x[b, r])
            for c in range(m):
                DY[c] = Y[b, i, c] - y_mean[b, c]
            for r in range(n):
                for c in range(m):
                    Pxy[r, c] += DX[r] * DY[c]
        kalman_gain_run(Pxy, Sy[b], K, Ys)
        for c in range(m):
            nu[b, c] = z[b, c] - y_mean[b, c]
        for r in range(n):
            corr[r] = 0.0
            for j in range(m):
                U[r, j] = 0.0
        for c in range(m):
            for r in range(n):
                corr[r] += K[r, c] * nu[b, c]
                for j in range(m):
                    U[r, j] += K[r, c] * Sy[b, c, j]
        for r in range(n):
            x_post[b, r] = x[b, r] + corr[r]
        failed[b] = cholupdate_run(S[b], U, 1.0, True, S_post[b], v)
