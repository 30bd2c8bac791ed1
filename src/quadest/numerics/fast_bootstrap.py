"""The bootstrap particle filter's fast step (``estimator.pf.kernel: fast``): weights,
normalisation, ESS, resampling, gather and moments fused into one pass per run.

The exact step (:meth:`quadest.estimators.particle.ParticleFilter.update`) keeps every number of
its numpy references bit for bit, which pins it to numpy's vectorised ``exp``, the references'
divisions and about ten passes over the particles. The fast step computes the same filter
(Gordon, Salmond & Smith 1993; the bootstrap weight is the likelihood ``p(y_k | x_k^i)``) with
scalar ``exp`` (libm's, which differs from numpy's in the last bit of about 5 % of values),
products by reciprocals (``1/Σ`` and ``1/N``), sequential sums and the uniforms of every run
drawn at every step; so its numbers differ from the exact mode's by round-off at first and, once
a resampling index flips, by Monte Carlo error: both are consistent estimators of the same
filter (tests/test_particle_fast_mode.py checks their mean RMSE agree within Monte Carlo error).

:func:`fast_bootstrap_step_reference` is the readable numpy reference; on the numba backend
(``QUADEST_KERNELS``) :func:`fast_bootstrap_step` runs the compiled
:func:`quadest.numerics.particle_kernels.bootstrap_fast_step_kernel`, which gives the reference's
numbers to round-off on the same uniforms and the same indices (a selection index could differ
only when a position lies within round-off of a cumulative weight).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache

import numpy as np

from quadest.numerics.draws import generator_list, particle_kernels

FAST_SCHEMES = ("multinomial", "systematic", "stratified")
SCHEME_CODES = {"multinomial": 0, "systematic": 1, "stratified": 2}


@dataclass
class FastStep:
    """What one fast step returns, per run: the cloud after the step ``x`` (B, N, n) (resampled
    runs: the picked particles), the normalised weights before resampling ``w`` (B, N), the ESS
    (B,), which runs ``resampled``, which ``vanished`` (every weight zero: equal weights instead),
    which were ``floored`` (no log-likelihood above ``log_floor``), and the estimate's ``mean``
    (B, n) and ``cov`` (B, n, n)."""

    x: np.ndarray
    w: np.ndarray
    ess: np.ndarray
    resampled: np.ndarray
    vanished: np.ndarray
    floored: np.ndarray
    mean: np.ndarray
    cov: np.ndarray


def measurement_whitening(R: np.ndarray) -> tuple[np.ndarray, float]:
    """``(L⁻¹, log_norm)`` for ``R = L Lᵀ``: the lower-triangular whitening of a measurement
    residual and the log of the Gaussian's normalising constant ``−(m/2) log 2π − Σ log Lⱼⱼ``."""
    L = np.linalg.cholesky(R)
    m = R.shape[0]
    return np.linalg.inv(L), float(-0.5 * m * np.log(2.0 * np.pi) - np.sum(np.log(np.diagonal(L))))


def draw_step_uniforms(scheme: str, rngs: Sequence[np.random.Generator], N: int) -> np.ndarray:
    """The uniforms (B, N) of one fast step, run ``b``'s from ``rngs[b]`` (``systematic``: one per
    run, in column 0), compiled on the numba backend (the same stream as numpy's ``random``)."""
    columns = 1 if scheme == "systematic" else N
    out = np.zeros((len(rngs), N))
    kernels = particle_kernels()
    if kernels is None:
        for rng, row in zip(rngs, out, strict=True):
            row[:columns] = rng.random(columns)
    else:
        target = np.empty((len(rngs), columns))
        kernels.uniform_kernel(generator_list(rngs), np.arange(len(rngs)), target)
        out[:, :columns] = target
    return out


def fast_bootstrap_step_reference(
    x: np.ndarray, hx: np.ndarray, z: np.ndarray, whitening: np.ndarray, log_norm: float,
    log_weights: np.ndarray, uniforms: np.ndarray, scheme: str, every_step: bool, threshold: float,
    active: np.ndarray, estimate_resampled: bool, log_floor: float, floor: bool,
) -> FastStep:  # fmt: skip
    """One fast step after the propagation, in numpy, for proposed particles ``x`` (B, N, n) with
    predicted measurements ``hx`` (B, N, m) and measurements ``z`` (B, m):

    1. log-likelihood ``log_norm − ½‖L⁻¹(z − h(xᵢ))‖²`` (``whitening = L⁻¹``, lower triangular,
       its zeros never multiplied: :func:`measurement_whitening`), with ``floor``: ``logaddexp(·, log_floor)`` (the
       ``weights: linear_floor`` numerics); plus the previous ``log_weights`` (B, N);
    2. weights ``exp(v − max v)`` over the finite ``v`` (non-finite: 0; none finite: the run
       vanished, equal weights), normalised by the product with ``1 / Σ``; ESS ``1 / Σ wᵢ²``;
    3. resampling of the ``active`` runs at every step (``every_step``) or when
       ESS < ``threshold``·N, by ``index = #{j : c_j ≤ u}`` on the cumulative weights ``c`` at
       the positions ``(i + Uᵢ)/N`` (stratified), ``(i + U₀)/N`` (systematic) or ``Uᵢ``
       (multinomial), ``uniforms`` (B, N);
    4. the estimate: mean and covariance of the weighted cloud, or with ``estimate_resampled`` of
       the resampled cloud (equal weights) for the runs that resampled.
    """
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        return _reference_step(x, hx, z, whitening, log_norm, log_weights, uniforms, scheme, every_step, threshold,
                               active, estimate_resampled, log_floor, floor)  # fmt: skip


def _reference_step(
    x: np.ndarray, hx: np.ndarray, z: np.ndarray, whitening: np.ndarray, log_norm: float,
    log_weights: np.ndarray, uniforms: np.ndarray, scheme: str, every_step: bool, threshold: float,
    active: np.ndarray, estimate_resampled: bool, log_floor: float, floor: bool,
) -> FastStep:  # fmt: skip
    """The body of :func:`fast_bootstrap_step_reference`."""
    N = x.shape[1]
    residual = z[:, None, :] - hx
    white = np.stack([residual[..., : j + 1] @ whitening[j, : j + 1] for j in range(z.shape[1])], axis=-1)
    likelihood = log_norm - 0.5 * np.sum(white**2, axis=-1)
    floored = ~np.any(likelihood > log_floor, axis=1)
    if floor:
        likelihood = np.logaddexp(likelihood, log_floor)
    v = log_weights + likelihood
    v = np.where(v < np.inf, v, -np.inf)
    top = np.max(v, axis=1)
    vanished = top == -np.inf
    e = np.where(vanished[:, None], 1.0, np.exp(v - np.where(vanished, 0.0, top)[:, None]))
    w = e * (1.0 / np.sum(e, axis=1))[:, None]
    ess = 1.0 / np.sum(w**2, axis=1)
    resampled = active & (every_step | (ess < threshold * N))
    x_out = x.copy()
    mean, cov = moments(x, w)
    positions = {
        "stratified": (np.arange(N) + uniforms) * (1.0 / N),
        "systematic": (np.arange(N) + uniforms[:, :1]) * (1.0 / N),
        "multinomial": uniforms,
    }[scheme]
    for b in np.flatnonzero(resampled):
        idx = np.minimum(np.searchsorted(np.cumsum(w[b]), positions[b], side="right"), N - 1)
        x_out[b] = x[b, idx]
        if estimate_resampled:
            mean[b], cov[b] = (a[0] for a in moments(x_out[b : b + 1], np.full((1, N), 1.0 / N)))
    return FastStep(x_out, w, ess, resampled, vanished, floored, mean, cov)


def moments(x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (B, n) and covariance (B, n, n) of clouds ``x`` (B, N, n) with weights ``w`` (B, N),
    particles of zero weight left out."""
    x = np.where(w[..., None] > 0, x, 0.0)
    mean = np.einsum("bk,bki->bi", w, x)
    d = np.where(w[..., None] > 0, x - mean[:, None, :], 0.0)
    cov = np.einsum("bk,bki,bkj->bij", w, d, d)
    return mean, 0.5 * (cov + np.swapaxes(cov, -1, -2))


def fast_bootstrap_step(
    x: np.ndarray, hx: np.ndarray, z: np.ndarray, whitening: np.ndarray, log_norm: float,
    log_weights: np.ndarray, uniforms: np.ndarray, scheme: str, every_step: bool, threshold: float,
    active: np.ndarray, estimate_resampled: bool, log_floor: float, floor: bool,
) -> FastStep:  # fmt: skip
    """:func:`fast_bootstrap_step_reference`, by the compiled kernel on the numba backend."""
    kernels = particle_kernels()
    if kernels is None:
        return fast_bootstrap_step_reference(
            x, hx, z, whitening, log_norm, log_weights, uniforms, scheme, every_step, threshold,
            active, estimate_resampled, log_floor, floor,
        )  # fmt: skip
    B, N, n = x.shape
    w = np.empty((B, N))
    vanished, floored = np.empty(B, dtype=np.bool_), np.empty(B, dtype=np.bool_)
    kernels.fast_log_weights_kernel(
        np.ascontiguousarray(hx, dtype=float), np.ascontiguousarray(z, dtype=float), whitening, log_norm,
        log_weights, log_floor, floor, w, vanished, floored,
    )  # fmt: skip
    np.exp(w, out=w)
    out = FastStep(
        np.empty_like(x), w, np.empty(B), np.empty(B, dtype=np.bool_), vanished, floored, np.empty((B, n)),
        np.empty((B, n, n)),
    )  # fmt: skip
    kernels.fast_resample_kernel(
        np.ascontiguousarray(x, dtype=float), w, uniforms, SCHEME_CODES[scheme], every_step, threshold, active,
        estimate_resampled, out.x, out.ess, out.resampled, out.mean, out.cov,
    )  # fmt: skip
    return out


@cache
def warm_up_fast_step() -> None:
    """Load the fast step's kernels now (compiling them if numba's cache is empty), with arguments
    of the types the filter passes, so that no timed step pays for it; nothing on the numpy backend."""
    if particle_kernels() is None:
        return
    rngs = [np.random.default_rng(0)]
    for scheme in FAST_SCHEMES:
        for flag in (False, True):
            fast_bootstrap_step(
                np.zeros((1, 2, 1)), np.zeros((1, 2, 1)), np.zeros((1, 1)), np.eye(1), 0.0, np.zeros((1, 2)),
                draw_step_uniforms(scheme, rngs, 2), scheme, flag, 0.5, np.ones(1, dtype=np.bool_), flag, 0.0, flag,
            )  # fmt: skip
