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
    ``out[b] out[b]ᵀ = A[b] A[b]ᵀ``.

    ``A`` (B, n, L) with L ≥ n. Row ``k`` of the working copy is reflected onto ``e_k`` by the
    Householder vector ``v = x − α e_1`` with ``α = −sign(x_0) ‖x‖`` (no cancellation in ``v_0``),
    applied to the rows below; ``S[k, k] = |α|`` and column ``k`` of ``S`` is multiplied by
    ``sign(α)``, which leaves ``S Sᵀ`` unchanged (the reference's sign fix, eqs 5.18, 5.23).
    ``W`` (n, L) is the scratch copy of one run.
    """
    _, n, L = A.shape
    for b in range(first, stop):
        for i in range(n):
            for j in range(L):
                W[i, j] = A[b, i, j]
            for j in range(n):
                out[b, i, j] = 0.0
        for k in range(n):
            sigma2 = 0.0
            for j in range(k, L):
                sigma2 += W[k, j] * W[k, j]
            sigma = math.sqrt(sigma2)
            if sigma == 0.0:  # the row is already zero from k on: nothing to reflect
                for i in range(k + 1, n):
                    out[b, i, k] = W[i, k]
                continue
            x0 = W[k, k]
            alpha = -sigma if x0 >= 0.0 else sigma
            v0 = x0 - alpha
            W[k, k] = v0
            beta = 1.0 / (sigma * (sigma + abs(x0)))  # 2 / vᵀv
            sign = -1.0 if alpha < 0.0 else 1.0
            out[b, k, k] = sigma
            for i in range(k + 1, n):
                dot = 0.0
                for j in range(k, L):
                    dot += W[i, j] * W[k, j]
                t = beta * dot
                for j in range(k, L):
                    W[i, j] -= t * W[k, j]
                out[b, i, k] = sign * W[i, k]


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
    """``out[b]`` for runs ``first ≤ b < stop``: the factor of ``S Sᵀ ± scale² Σ_j x_j x_jᵀ`` for
    the columns ``x_j`` of ``X[b]``.

    ``S`` (B, n, n), ``X`` (B, n, k). The arithmetic of each pivot is the reference's (eq. 5.29):
    ``r = √(L_kk² ± v_k²)``, ``c = r / L_kk``, ``s = v_k / L_kk``, ``col = (col ± s v) / c``,
    ``v = c v − s col``. A run whose result has a non-positive or NaN diagonal or a non-finite entry
    (a failed downdate, or a NaN input) gets ``failed[b] = True`` and its input factor back.
    ``v`` (n,) is the scratch column.
    """
    n = S.shape[1]
    k = X.shape[2]
    for b in range(first, stop):
        for i in range(n):
            for j in range(n):
                out[b, i, j] = S[b, i, j]
        for j in range(k):
            for i in range(n):
                v[i] = X[b, i, j] * scale
            for p in range(n):
                Lpp = out[b, p, p]
                vp = v[p]
                r2 = Lpp * Lpp
                v2 = vp * vp
                r = math.sqrt(r2 - v2) if downdate else math.sqrt(r2 + v2)
                c = r / Lpp
                s = vp / Lpp
                signed_s = -s if downdate else s
                out[b, p, p] = r
                for i in range(p + 1, n):
                    col = (out[b, i, p] + signed_s * v[i]) / c
                    out[b, i, p] = col
                    v[i] = v[i] * c - s * col
        bad = False
        for i in range(n):
            if not out[b, i, i] > 0.0:
                bad = True
            for j in range(n):
                if not math.isfinite(out[b, i, j]):
                    bad = True
        failed[b] = bad
        if bad:
            for i in range(n):
                for j in range(n):
                    out[b, i, j] = S[b, i, j]


@njit(**_JIT)
def kalman_gain_kernel(Pxy: np.ndarray, Sy: np.ndarray, K: np.ndarray) -> None:
    """``K[b] Sy[b] Sy[b]ᵀ = Pxy[b]`` (eq. 5.26) for every row ``i`` of ``K[b]``: ``Sy y = Pxy[b, i]``
    forward, then ``Syᵀ K[b, i] = y`` backward. ``Pxy`` (B, n, m), ``Sy`` (B, m, m) lower triangular.

    The rows are solved side by side (the loop over ``i`` innermost), so that their divisions are
    independent and overlap in the processor; each element is computed as in a row-by-row solve,
    ``y_r = (b_r − Σ_{c<r} Sy_rc y_c) / Sy_rr`` with the sum in increasing ``c``.
    """
    B, n, m = Pxy.shape
    Y = np.empty((n, m))
    for b in range(B):
        for r in range(m):
            d = Sy[b, r, r]
            for i in range(n):
                acc = Pxy[b, i, r]
                for c in range(r):
                    acc -= Sy[b, r, c] * Y[i, c]
                Y[i, r] = acc / d
        for r in range(m - 1, -1, -1):
            d = Sy[b, r, r]
            for i in range(n):
                acc = Y[i, r]
                for c in range(r + 1, m):
                    acc -= Sy[b, c, r] * K[b, i, c]
                K[b, i, r] = acc / d


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
