"""Compiled kernels (numba) for the particle filters' per-step work, one run after the other.

Each kernel of the exact path gives exactly what its numpy reference gives, bit for bit
(tests/test_particle_kernels.py); the fast step's kernels (the last list) give their reference's
numbers to round-off (tests/test_particle_fast_mode.py):

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

The fast step of ``pf`` with ``kernel: fast`` (reference:
:func:`quadest.numerics.fast_bootstrap.fast_bootstrap_step_reference`):

- :func:`uniform_kernel` — each run's uniforms from its own generator (numpy's ``random`` stream);
- :func:`fast_log_weights_kernel` — log-likelihood, previous log-weights, the shift by the maximum;
- :func:`fast_resample_kernel` — after numpy's ``exp``: normalisation by a reciprocal product, ESS,
  selection (:func:`_strata`, :func:`_search`), gather and moments in one pass per run. Sums may be
  reassociated (``fastmath`` without the no-NaN and no-∞ flags, so NaN and ±∞ keep their meaning).

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
# the fast step's kernels may reassociate sums (vectorised, not bit for bit); NaN and ±∞ keep their meaning
_FAST_JIT = {**_JIT, "fastmath": {"reassoc", "contract", "arcp", "nsz"}}

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
def gaussian_logpdf_diagonal_kernel(
    e: np.ndarray, inverse_scale: np.ndarray, constant: float, log_det: float, out: np.ndarray
) -> None:
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
def shift_log_weights_kernel(
    log_weights: np.ndarray, increments: np.ndarray, out: np.ndarray, vanished: np.ndarray
) -> None:
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


@njit(**_JIT)
def uniform_kernel(rngs, runs: np.ndarray, out: np.ndarray) -> None:
    """``out[r] = rngs[runs[r]].random(K)`` for every row ``r`` of ``out`` (R, K)."""
    for r in range(out.shape[0]):
        generator = rngs[runs[r]]
        for k in range(out.shape[1]):
            out[r, k] = generator.random()


@njit(**_FAST_JIT)
def _cloud_moments(x: np.ndarray, w: np.ndarray, uniform: bool, mean: np.ndarray, cov: np.ndarray) -> None:
    """Mean and covariance of the cloud ``x`` (N, n) with weights ``w`` (equal weights 1/N when
    ``uniform``); particles of zero weight are left out (they may be non-finite). One scalar sum
    per entry over the particles, so that the sums vectorise."""
    N, n = x.shape
    inverse_n = 1.0 / N
    for j in range(n):
        total = 0.0
        for i in range(N):
            wi = inverse_n if uniform else w[i]
            total += wi * x[i, j] if wi > 0 else 0.0
        mean[j] = total
    for j in range(n):
        for k in range(j + 1):
            total = 0.0
            for i in range(N):
                wi = inverse_n if uniform else w[i]
                total += wi * (x[i, j] - mean[j]) * (x[i, k] - mean[k]) if wi > 0 else 0.0
            cov[j, k] = total
            cov[k, j] = total


@njit(**_FAST_JIT)
def fast_log_weights_kernel(
    hx: np.ndarray,
    z: np.ndarray,
    whitening: np.ndarray,
    log_norm: float,
    log_weights: np.ndarray,
    log_floor: float,
    floor: bool,
    shifted: np.ndarray,
    vanished: np.ndarray,
    floored: np.ndarray,
) -> None:
    """The first pass of the fast bootstrap step (``kernel: fast``), per run: the log-likelihood
    ``log_norm − ½‖L⁻¹(z − h(xᵢ))‖²`` (``whitening = L⁻¹`` lower triangular), floored with
    ``floor``, plus ``log_weights``, shifted by its finite maximum into ``shifted`` (non-finite:
    −∞; a ``vanished`` run, none finite: zeros), and whether no log-likelihood exceeded
    ``log_floor`` (``floored``). Steps 1–2 of
    :func:`quadest.numerics.fast_bootstrap.fast_bootstrap_step_reference` before its ``exp``."""
    B, N, m = hx.shape
    for b in range(B):
        any_above = False
        top = -np.inf
        for i in range(N):
            if m == 1:
                white = whitening[0, 0] * (z[b, 0] - hx[b, i, 0])
                maha = white * white
            else:
                maha = 0.0
                for j in range(m):
                    acc = 0.0
                    for k in range(j + 1):
                        acc += whitening[j, k] * (z[b, k] - hx[b, i, k])
                    maha += acc * acc
            value = log_norm - 0.5 * maha
            any_above |= value > log_floor
            if floor and value == value:  # logaddexp(value, log_floor); NaN stays NaN
                high, low = (value, log_floor) if value > log_floor else (log_floor, value)
                value = high + np.log1p(np.exp(low - high)) if low > -np.inf else high
            value += log_weights[b, i]
            shifted[b, i] = value
            if value > top and value < np.inf:
                top = value
        floored[b] = not any_above
        vanished[b] = top == -np.inf
        for i in range(N):
            value = shifted[b, i]
            shifted[b, i] = 0.0 if vanished[b] else (value - top if value < np.inf else -np.inf)


@njit(**_FAST_JIT)
def fast_resample_kernel(
    x: np.ndarray,
    w: np.ndarray,
    uniforms: np.ndarray,
    scheme: int,
    every_step: bool,
    threshold: float,
    active: np.ndarray,
    estimate_resampled: bool,
    x_out: np.ndarray,
    ess: np.ndarray,
    resampled: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
) -> None:
    """The second pass of the fast bootstrap step, per run: the unnormalised weights ``w`` (B, N)
    normalised in place by the product with ``1/Σ``, the ESS, then for the runs due the selection
    ``#{j : c_j ≤ u}`` on the cumulative weights (:func:`_strata`, :func:`_search`), the gather into
    ``x_out`` (other runs: a copy) and the estimate's moments. Steps 2–4 of
    :func:`quadest.numerics.fast_bootstrap.fast_bootstrap_step_reference` after its ``exp``."""
    B, N, n = x.shape
    c = np.empty(N)
    padded = np.empty(N + 2)
    counts = np.empty(N + 1, dtype=np.intp)
    idx = np.empty(N, dtype=np.intp)
    for b in range(B):
        total = 0.0
        for i in range(N):
            total += w[b, i]
        scale = 1.0 / total
        squares = 0.0
        running = 0.0
        for i in range(N):
            wi = w[b, i] * scale
            w[b, i] = wi
            squares += wi * wi
            running += wi
            c[i] = running
        ess[b] = 1.0 / squares
        due = active[b] and (every_step or ess[b] < threshold * N)
        resampled[b] = due
        if not estimate_resampled or not due:
            _cloud_moments(x[b], w[b], False, mean[b], cov[b])
        if not due:
            x_out[b] = x[b]
            continue
        if scheme == MULTINOMIAL:
            for i in range(N):
                idx[i] = _search(c, uniforms[b, i])
        else:
            _strata(c, uniforms[b], scheme == SYSTEMATIC, padded, counts, idx)
        for i in range(N):
            k = idx[i]
            for j in range(n):
                x_out[b, i, j] = x[b, k, j]
        if estimate_resampled:
            _cloud_moments(x_out[b], w[b], True, mean[b], cov[b])
