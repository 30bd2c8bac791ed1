"""Compiled kernels (numba) for the particle filters' per-step work, one run after the other.

Each kernel gives exactly what its numpy reference gives, bit for bit (tests/test_particle_kernels.py):

- :func:`standard_normal_kernel` — what ``rngs[b].standard_normal(out[b].shape)`` draws, for the
  runs ``runs`` (numba's ``np.random.Generator`` runs numpy's own algorithms on the generator's
  bit generator, so the stream and the generator's state afterwards are the same). Reference: the
  per-run loop of :func:`quadest.numerics.draws.standard_normals`.
- :func:`resample_kernel` — the four schemes of :mod:`quadest.numerics.resampling` on the same
  uniforms: the cumulative weights summed in the same order (numpy's ``cumsum`` is sequential)
  and divided by their last entry, and the selection rule ``index = #{j : c_j ≤ u}``, evaluated
  by counting for the sorted stratified and systematic positions and by a binary search for the
  others. Reference: :func:`~quadest.numerics.resampling.resample_from_uniforms`. The uniforms
  come from numpy (:func:`~quadest.numerics.resampling.draw_uniforms`).
- :func:`gather_kernel` — the particles of each resampled run picked by their ancestor indices
  (a copy: exact). Reference: :func:`quadest.estimators.particle.gather_particles`.
- :func:`gaussian_logpdf_diagonal_kernel` — the log-density of Gaussian noise with a diagonal
  covariance. Reference: :func:`quadest.models.base._gaussian_logpdf`.
- :func:`shift_log_weights_kernel` and :func:`normalise_kernel` — around numpy's ``exp``, the
  normalised weights and the ESS. References:
  :func:`~quadest.numerics.resampling.normalise_log_weights` and
  :func:`~quadest.numerics.resampling.effective_sample_size`. Alone they are about 10 % slower
  than numpy's vectorised passes; inside the filter's step, where they save the temporaries, the
  step is about 1 ns per particle faster with them (docs/benchmarks.md).

Why a compiled step pays here: the numpy path makes ~10 passes over the particles for one
resampling; the kernels make one pass per run while its particles are in cache. Threads: ``parallel=True``
with ``prange`` over the runs drew normals 30× slower than the serial loop on the development
machine (numba's generator objects inside a parallel region), so the kernels are serial
(docs/benchmarks.md). ``cache=True`` keeps the machine code on disk; the generators are passed as
a ``numba.typed.List`` (:func:`quadest.numerics.draws.generator_list`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_JIT = {"cache": True, "error_model": "numpy", "nogil": True}

MULTINOMIAL, SYSTEMATIC, STRATIFIED, RESIDUAL = 0, 1, 2, 3


@njit(**_JIT)
def standard_normal_kernel(rngs, runs: np.ndarray, out: np.ndarray) -> None:
    """``out[r] = rngs[runs[r]].standard_normal(K)`` for every row ``r`` of ``out`` (R, K)."""
    for r in range(out.shape[0]):
        rng = rngs[runs[r]]
        for k in range(out.shape[1]):
            out[r, k] = rng.standard_normal()


@njit(**_JIT)
def _cumulative(weights: np.ndarray, c: np.ndarray) -> None:
    """``c = cumsum(weights) / cumsum(weights)[-1]``, summed left to right as numpy does."""
    total = 0.0
    for j in range(weights.size):
        total += weights[j]
        c[j] = total
    last = c[weights.size - 1]
    for j in range(weights.size):
        c[j] /= last


@njit(**_JIT)
def _search(c: np.ndarray, u: float) -> int:
    """``min(#{j : c_j ≤ u}, N − 1)`` for nondecreasing ``c`` (``np.searchsorted(c, u, "right")``)."""
    lo, hi = 0, c.size
    while lo < hi:
        mid = (lo + hi) >> 1
        if c[mid] <= u:
            lo = mid + 1
        else:
            hi = mid
    return min(lo, c.size - 1)


@njit(**_JIT)
def _strata(
    c: np.ndarray, u: np.ndarray, systematic: bool, padded: np.ndarray, counts: np.ndarray, out: np.ndarray
) -> None:
    """The stratified (or systematic, ``u[0]`` for all) selection ``#{j : c_j ≤ u_i}`` at the
    positions ``u_i = fl(fl(i + U_i)/N)``, by the counting argument of
    :func:`~quadest.numerics.resampling._select_in_strata` (no data-dependent branch: a merge of the
    sorted positions with ``c`` mispredicts about once per particle). ``padded`` (N + 2) and
    ``counts`` (N + 1) are scratch."""
    N = c.size
    padded[0], padded[N + 1] = -np.inf, np.inf
    for i in range(N):
        padded[i + 1] = (i + (u[0] if systematic else u[i])) / N
    counts[:] = 0
    for j in range(N):
        m = int(c[j] * N)
        counts[m - 1 + (padded[m] < c[j]) + (padded[m + 1] < c[j])] += 1
    total = 0
    for i in range(N):
        total += counts[i]
        out[i] = min(total, N - 1)


@njit(**_JIT)
def _residual(w: np.ndarray, u: np.ndarray, c: np.ndarray, remainder: np.ndarray, out: np.ndarray) -> None:
    """Residual resampling (Liu & Chen 1998): ``⌊N wᵢ⌋`` copies of particle i in order, then the
    positions ``kept..N−1`` by multinomial selection on the residual weights from ``u[0..]``."""
    N = w.size
    kept = 0
    positive = False
    for i in range(N):
        scaled = N * w[i]
        copies = int(np.floor(scaled))
        remainder[i] = scaled - copies
        positive |= remainder[i] > 0
        for _ in range(copies):
            if kept < N:
                out[kept] = i
            kept += 1
    if not positive:
        remainder[:] = 1.0
    _cumulative(remainder, c)
    for k in range(min(kept, N), N):
        out[k] = _search(c, u[k - kept])


@njit(**_JIT)
def resample_kernel(scheme: int, weights: np.ndarray, uniforms: np.ndarray, out: np.ndarray) -> None:
    """Ancestor indices ``out[r]`` (N,) of the normalised weights ``weights[r]`` (R, N) from the
    uniforms ``uniforms[r]`` (column 0 only for ``systematic``; the first ``N − Σ⌊N wᵢ⌋`` for
    ``residual``), as :func:`~quadest.numerics.resampling.resample_from_uniforms`."""
    R, N = weights.shape
    c = np.empty(N)
    remainder = np.empty(N)
    padded = np.empty(N + 2)
    counts = np.empty(N + 1, dtype=np.intp)
    for r in range(R):
        if scheme == RESIDUAL:
            _residual(weights[r], uniforms[r], c, remainder, out[r])
            continue
        _cumulative(weights[r], c)
        if scheme == MULTINOMIAL:
            for i in range(N):
                out[r, i] = _search(c, uniforms[r, i])
        else:
            _strata(c, uniforms[r], scheme == SYSTEMATIC, padded, counts, out[r])


@njit(**_JIT)
def gather_kernel(particles: np.ndarray, runs: np.ndarray, indices: np.ndarray, out: np.ndarray) -> None:
    """``out[runs[r], i] = particles[runs[r], indices[r, i]]`` for the runs' particle arrays
    ``particles`` (B, N, D); ``out`` may be ``particles`` itself (each run is copied aside first)."""
    _, N, D = particles.shape
    in_place = out is particles
    old = np.empty((N, D)) if in_place else particles[0]
    for r in range(runs.size):
        b = runs[r]
        source = particles[b]
        if in_place:
            old[:, :] = source
            source = old
        target = out[b]
        for i in range(N):
            k = indices[r, i]
            for d in range(D):
                target[i, d] = source[k, d]


@njit(**_JIT)
def gaussian_logpdf_diagonal_kernel(e: np.ndarray, inverse_scale: np.ndarray, constant: float, log_det: float,
                                    out: np.ndarray) -> None:  # fmt: skip
    """``out[k] = −0.5 (Σ_j (e[k, j] · inverse_scale[j])² + constant) − log_det`` for ``e`` (K, r):
    ``log N(e; 0, diag(scale²))`` with ``constant = r log 2π`` and ``log_det = Σ log scale``, the
    operations of :func:`quadest.models.base._gaussian_logpdf`'s diagonal branch, the sum over
    ``j`` as numpy's pairwise summation forms it."""
    K, r = e.shape
    squares = np.empty(r)
    tasks, partial = np.empty((64, 3), dtype=np.int64), np.empty(64)
    for k in range(K):
        if r < 8:  # numpy sums fewer than 8 terms left to right
            maha = 0.0
            for j in range(r):
                white = e[k, j] * inverse_scale[j]
                maha += white * white
        else:
            for j in range(r):
                white = e[k, j] * inverse_scale[j]
                squares[j] = white * white
            maha = _block_sum(squares, 0, r) if r <= 128 else _pairwise_sum(squares, tasks, partial)
        out[k] = -0.5 * (maha + constant) - log_det


@njit(**_JIT)
def shift_log_weights_kernel(log_weights: np.ndarray, increments: np.ndarray, out: np.ndarray,
                             vanished: np.ndarray) -> None:  # fmt: skip
    """``out = log_weights + increments − max`` per run (B, N), the maximum over the finite entries,
    non-finite entries −∞; a run with none finite is ``vanished`` and gets zeros (so that ``exp``
    gives it equal weights): the part of
    :func:`~quadest.numerics.resampling.normalise_log_weights` before its ``exp``."""
    B, N = out.shape
    for b in range(B):
        top = -np.inf
        for i in range(N):
            value = log_weights[b, i] + increments[b, i]
            out[b, i] = value
            if value > top and value < np.inf:  # finite: NaN compares false, −∞ never exceeds top
                top = value
        vanished[b] = top == -np.inf
        if vanished[b]:
            out[b, :] = 0.0
            continue
        for i in range(N):
            value = out[b, i]
            out[b, i] = value - top if value < np.inf else -np.inf  # NaN and +∞ → −∞; −∞ stays


@njit(**_JIT)
def _block_sum(a: np.ndarray, first: int, n: int) -> float:
    """A leaf of numpy's ``pairwise_sum`` (n ≤ 128): sequential below 8 terms, else eight
    accumulators, combined pairwise, then the remainder."""
    if n < 8:
        total = 0.0
        for i in range(first, first + n):
            total += a[i]
        return total
    r0, r1, r2, r3 = a[first], a[first + 1], a[first + 2], a[first + 3]
    r4, r5, r6, r7 = a[first + 4], a[first + 5], a[first + 6], a[first + 7]
    for i in range(first + 8, first + n - n % 8, 8):
        r0, r1, r2, r3 = r0 + a[i], r1 + a[i + 1], r2 + a[i + 2], r3 + a[i + 3]
        r4, r5, r6, r7 = r4 + a[i + 4], r5 + a[i + 5], r6 + a[i + 6], r7 + a[i + 7]
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(first + n - n % 8, first + n):
        total += a[i]
    return total


@njit(**_JIT)
def _pairwise_sum(a: np.ndarray, tasks: np.ndarray, partial: np.ndarray) -> float:
    """``a.sum()`` as numpy computes it, bit for bit: numpy's ``pairwise_sum``, which halves a
    range (at a multiple of 8) until it has at most 128 terms and adds the halves' sums. Written
    with an explicit stack (numba's on-disk cache mishandles recursion): ``tasks`` (64, 3) holds
    (first, n, 0) to sum a range and (0, 0, 1) to add the last two partial sums, ``partial`` (64,)."""
    top, count = 1, 0
    tasks[0, 0], tasks[0, 1], tasks[0, 2] = 0, a.size, 0
    while top > 0:
        top -= 1
        first, n, combine = tasks[top, 0], tasks[top, 1], tasks[top, 2]
        if combine:
            count -= 1
            partial[count - 1] += partial[count]
        elif n <= 128:
            partial[count] = _block_sum(a, first, n)
            count += 1
        else:
            half = n // 2
            half -= half % 8
            tasks[top, 0], tasks[top, 1], tasks[top, 2] = 0, 0, 1
            tasks[top + 1, 0], tasks[top + 1, 1], tasks[top + 1, 2] = first + half, n - half, 0
            tasks[top + 2, 0], tasks[top + 2, 1], tasks[top + 2, 2] = first, half, 0
            top += 3
    return partial[0]


@njit(**_JIT)
def normalise_kernel(weights: np.ndarray, squares: np.ndarray, ess: np.ndarray) -> None:
    """In place, per run: ``weights /= Σ weights`` and Kish's ``ess = 1 / Σ wᵢ²`` (``squares`` (N,)
    is scratch), summed as numpy sums: the rest of
    :func:`~quadest.numerics.resampling.normalise_log_weights` after its ``exp``, and
    :func:`~quadest.numerics.resampling.effective_sample_size`."""
    B, N = weights.shape
    tasks, partial = np.empty((64, 3), dtype=np.int64), np.empty(64)
    for b in range(B):
        row = weights[b]
        total = _pairwise_sum(row, tasks, partial)
        for i in range(N):
            row[i] /= total
            squares[i] = row[i] * row[i]
        ess[b] = 1.0 / _pairwise_sum(squares, tasks, partial)
