"""Particle resampling, batched over Monte Carlo runs: weights (B, N) → ancestor indices (B, N).

Four schemes (Douc, Cappé & Moulines 2005, "Comparison of resampling schemes for particle
filtering"; Hol, Schön & Gustafsson 2006):

- ``multinomial`` (roulette wheel): N independent uniforms, each picks the particle whose slice
  of the cumulative weights contains it;
- ``stratified``: one uniform in each stratum ``[(i + U_i)/N]``;
- ``systematic``: one uniform for all strata, ``(i + U)/N``;
- ``residual`` (Liu & Chen 1998, JASA 93(443)): ``⌊N wᵢ⌋`` deterministic copies, the remaining
  ``N − Σ⌊N wᵢ⌋`` drawn by multinomial resampling from the residual weights
  ``(N wᵢ − ⌊N wᵢ⌋) / (N − Σ⌊N wⱼ⌋)``.

Every scheme is unbiased: the expected number of copies of particle i is ``N wᵢ``.

Two forms: :func:`resample` draws from one ``np.random.Generator`` per run (so a run resampled in
a batch gets exactly the indices it gets alone; on the numba backend its selection is the compiled
:func:`quadest.numerics.particle_kernels.resample_kernel`, which gives the same indices),
:func:`resample_from_uniforms`, the numpy reference, takes the
uniforms (B, N) explicitly (``systematic`` reads column 0 only; ``residual`` reads the first
``N − Σ⌊N wᵢ⌋`` columns of each row). The selection rule is ``index = #{j : c_j ≤ u}`` with ``c``
the cumulative weights (divided by their total, so the last is exactly 1), the rule of ``filterpy.monte_carlo``, so
both give the same indices on the same uniforms (filterpy's ``residual_resample`` computes its
residual weights as ``w − ⌊N w⌋`` instead of ``N w − ⌊N w⌋``, filterpy issue #290; its
deterministic part is right). ``stratified`` and ``systematic`` evaluate the rule exactly in
linear time (:func:`_select_in_strata`), the others by binary search.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from quadest.errors import ConfigError
from quadest.numerics.draws import all_runs, particle_kernels

RESAMPLING_SCHEMES = ("multinomial", "systematic", "stratified", "residual")
BLOCK_PARTICLES = 1 << 14  # particles resampled at once (128 KiB per float64 temporary)


def check_scheme(scheme: str, key: str = "resampling") -> None:
    """Raise :class:`ConfigError` unless ``scheme`` is one of :data:`RESAMPLING_SCHEMES`."""
    if scheme not in RESAMPLING_SCHEMES:
        raise ConfigError(key, scheme, f"one of {list(RESAMPLING_SCHEMES)}")


def effective_sample_size(weights: np.ndarray) -> np.ndarray:
    """Kish's effective sample size ``1 / Σ wᵢ²`` of normalised weights (..., N) → (...)."""
    return 1.0 / np.sum(weights**2, axis=-1)


def normalised_weights(log_weights: np.ndarray, increments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised weights (B, N) of ``log_weights + increments``, the vanished runs (B,) and the
    ESS (B,): :func:`normalise_log_weights` and :func:`effective_sample_size`, the references, or
    on the numba backend the same numbers bit for bit in three passes (two compiled kernels of
    :mod:`quadest.numerics.particle_kernels` around numpy's ``exp``)."""
    kernels = particle_kernels()
    if kernels is None:
        w, vanished = normalise_log_weights(log_weights + increments)
        return w, vanished, effective_sample_size(w)
    B, N = log_weights.shape
    w, vanished, ess = np.empty((B, N)), np.empty(B, dtype=bool), np.empty(B)
    kernels.shift_log_weights_kernel(np.ascontiguousarray(log_weights), np.ascontiguousarray(increments), w, vanished)
    np.exp(w, out=w)
    kernels.normalise_kernel(w, np.empty(N), ess)
    return w, vanished, ess


def normalise_log_weights(log_weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised weights (B, N) from log-weights, shifted by each run's maximum, and the mask
    (B,) of runs whose weights all vanished (every log-weight −∞ or NaN); those rows get
    uniform weights so the arithmetic of the batch stays finite."""
    finite = np.isfinite(log_weights)
    vanished = ~finite.any(axis=-1)
    w = np.where(finite, log_weights, -np.inf)
    top = np.max(w, axis=-1, keepdims=True)
    top[vanished] = 0.0
    w -= top
    np.exp(w, out=w)
    w[vanished] = 1.0
    w /= w.sum(axis=-1, keepdims=True)
    return w, vanished


def _cumulative(weights: np.ndarray) -> np.ndarray:
    c = np.cumsum(weights, axis=-1)
    c /= c[:, -1:]  # the last entry is exactly 1 (x / x), so no uniform in [0, 1) falls beyond it
    return c


def _select(cumulative: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """``#{j : c_j ≤ u}`` for every position ``u`` of every run, in any order (multinomial, the
    random part of residual): one exact binary search per run (a loop over runs, not particles)."""
    N = cumulative.shape[1]
    out = np.stack([np.searchsorted(c, u, side="right") for c, u in zip(cumulative, positions, strict=True)])
    return np.minimum(out, N - 1).reshape(positions.shape)


def _select_in_strata(cumulative: np.ndarray, uniforms: np.ndarray, systematic: bool) -> np.ndarray:
    """:func:`_select` for the positions ``u_i = fl(fl(i + U_i) / N)`` with ``U_i = uniforms[:, i]``
    in [0, 1) (stratified), or ``uniforms[:, 0]`` for every i (systematic), exactly and in linear
    time for all runs at once.

    Such a position lies in its stratum, ``fl(i/N) ≤ u_i ≤ fl((i+1)/N)``, so the positions are sorted
    and, for each cumulative weight ``c_j`` with ``m = ⌊fl(N c_j)⌋``, every ``i ≤ m − 2`` has
    ``u_i < c_j`` (for N < 2⁵²) and no ``i ≥ m + 1`` has (``c_j < (m+1)/N`` exactly, so
    ``u_i ≥ fl((m+1)/N) ≥ c_j``): ``K_j = #{i : u_i < c_j} = m − 1 + [u_{m−1} < c_j] + [u_m < c_j]``,
    read from the positions padded with −∞ in front and +∞ behind (which count the missing
    ``u_{−1}`` as below and ``u_N`` as not). Then ``#{j : c_j ≤ u_i} = #{j : K_j ≤ i}``, a
    cumulative count of the ``K_j`` (one ``bincount`` over the batch, each run offset by ``N + 1``)."""
    B, N = cumulative.shape
    padded = np.empty((B, N + 2))
    padded[:, 0], padded[:, -1] = -np.inf, np.inf
    positions = padded[:, 1:-1]
    np.add(np.arange(N)[None, :], uniforms[:, :1] if systematic else uniforms, out=positions)
    positions /= N
    run = np.arange(B)[:, None]
    at = (cumulative * N).astype(np.intp)  # m, in [0, N]: 0 ≤ c_j ≤ 1
    at += (N + 2) * run  # padded u_{m−1}
    flat = padded.ravel()
    below = (flat[at] < cumulative).astype(np.intp)
    at += 1  # padded u_m
    below += flat[at] < cumulative
    below += at
    below -= run + 2  # K_j + (N + 1) b
    counts = np.bincount(below.ravel(), minlength=B * (N + 1)).reshape(B, N + 1)[:, :N]
    return np.minimum(np.cumsum(counts, axis=1), N - 1)


def _residual(weights: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
    B, N = weights.shape
    scaled = N * weights
    copies = np.floor(scaled).astype(np.intp)
    kept = copies.sum(axis=1)  # deterministic draws per run
    # deterministic part: position k < kept takes the first i with cumsum(copies)_i > k (integers: exact)
    stride = N + 1
    ends = (np.cumsum(copies, axis=1) + stride * np.arange(B)[:, None]).ravel()
    slots = np.arange(N)[None, :] + stride * np.arange(B)[:, None]
    fixed = np.searchsorted(ends, slots.ravel(), side="right").reshape(B, N) - N * np.arange(B)[:, None]
    # random part: positions kept..N-1 read uniforms 0..N-1-kept
    remainder = scaled - copies
    total = remainder.sum(axis=1, keepdims=True)
    remainder = np.where(total > 0, remainder, 1.0)
    shifted = np.take_along_axis(uniforms, np.clip(np.arange(N)[None, :] - kept[:, None], 0, N - 1), axis=1)
    drawn = _select(_cumulative(remainder), shifted)
    return np.where(np.arange(N)[None, :] < kept[:, None], np.minimum(fixed, N - 1), drawn)


def _resample_block(scheme: str, weights: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
    if scheme == "residual":
        return _residual(weights, uniforms)
    if scheme == "multinomial":
        return _select(_cumulative(weights), uniforms)
    return _select_in_strata(_cumulative(weights), uniforms, systematic=scheme == "systematic")


def resample_from_uniforms(scheme: str, weights: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
    """Ancestor indices (B, N) of normalised ``weights`` (B, N) from explicit ``uniforms`` (B, N)
    in [0, 1) (see the module docstring for which columns each scheme reads).

    Runs are resampled independently, in blocks of about :data:`BLOCK_PARTICLES` particles: the
    temporaries of a block stay in the processor's cache and, at 128 KiB, below glibc's default
    threshold for serving an allocation by ``mmap`` (a fresh mapping page-faults on first touch).
    On the development machine that takes the selection for 100 runs × 1000 particles from
    ≈ 24 ns (one pass) and ≈ 15 ns (blocks of 2¹⁵) to ≈ 8 ns per particle, measured alone
    (``docs/benchmarks.md``)."""
    check_scheme(scheme)
    weights = np.asarray(weights, dtype=float)
    uniforms = np.asarray(uniforms, dtype=float)
    B, N = weights.shape
    runs = max(1, BLOCK_PARTICLES // N)
    if B <= runs:
        return _resample_block(scheme, weights, uniforms)
    out = np.empty((B, N), dtype=np.intp)
    for start in range(0, B, runs):
        block = slice(start, start + runs)
        out[block] = _resample_block(scheme, weights[block], uniforms[block])
    return out


def draw_uniforms(scheme: str, rngs: Sequence[np.random.Generator], N: int) -> np.ndarray:
    """The uniforms (B, N) a scheme reads, run ``b``'s from ``rngs[b]`` (``systematic`` draws one
    per run and leaves the other columns at 0)."""
    check_scheme(scheme)
    if scheme == "systematic":
        out = np.zeros((len(rngs), N))
        out[:, 0] = [rng.random() for rng in rngs]
        return out
    out = np.empty((len(rngs), N))
    for rng, row in zip(rngs, out, strict=True):
        rng.random(out=row)
    return out


def resample(
    scheme: str, weights: np.ndarray, rngs: Sequence[np.random.Generator], runs: np.ndarray | None = None
) -> np.ndarray:
    """Ancestor indices (R, N) of normalised ``weights`` (R, N), row ``r`` drawing from
    ``rngs[runs[r]]`` (``runs``: every run of ``rngs`` when ``None``).

    The selection runs in one compiled pass per run on the numba backend
    (:func:`quadest.numerics.particle_kernels.resample_kernel`), as :func:`resample_from_uniforms`,
    the reference, on the numpy backend; both give the same indices from the same uniforms."""
    check_scheme(scheme)
    weights = np.asarray(weights, dtype=float)
    uniforms = draw_uniforms(scheme, [rngs[b] for b in all_runs(rngs, runs)], weights.shape[1])
    kernels = particle_kernels()
    if kernels is None:
        return resample_from_uniforms(scheme, weights, uniforms)
    out = np.empty(weights.shape, dtype=np.intp)
    code = {
        "multinomial": kernels.MULTINOMIAL,
        "systematic": kernels.SYSTEMATIC,
        "stratified": kernels.STRATIFIED,
        "residual": kernels.RESIDUAL,
    }[scheme]
    kernels.resample_kernel(code, np.ascontiguousarray(weights), uniforms, out)
    return out
