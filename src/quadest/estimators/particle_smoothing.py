"""Forward-filtering backward-simulation (FFBSi), batched over Monte Carlo runs.

Godsill, Doucet & West (2004), "Monte Carlo smoothing for nonlinear time series", JASA 99(465),
Algorithm 1: after a particle filter has run forward and kept its weighted clouds
``{x_k^i, w_k^i}`` (before resampling), ``M`` trajectories are drawn backwards:

    x̃_K ~ Σ_i w_K^i δ(x − x_K^i),
    x̃_k ~ Σ_i w_{k|k+1}^i δ(x − x_k^i),   w_{k|k+1}^i ∝ w_k^i p(x̃_{k+1} | x_k^i),

with the model's transition density ``p(x_{k+1} | x_k) = p_w(x_{k+1} − f(x_k, u))`` (additive
process noise, as the particle filters' weights assume). The smoothed mean and covariance of each
step are those of the M trajectories. Cost: ``O(N · M)`` transition densities per step and run
(every trajectory weighs every particle), ``N`` evaluations of ``f``; memory for the K clouds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from quadest.models.base import FilterModel
from quadest.numerics.resampling import draw_uniforms


@dataclass(frozen=True)
class ParticleCloud:
    """A filter's weighted cloud at one step: particles (B, N, n), normalised weights (B, N), and
    the input ``u`` (B, nu) of the transition *into* this step."""

    particles: np.ndarray
    weights: np.ndarray
    input: np.ndarray


def _categorical(weights: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
    """Indices (B, M) drawn from the rows of ``weights`` (B, M, N) by inversion of uniforms (B, M)."""
    cumulative = np.cumsum(weights, axis=-1)
    cumulative /= cumulative[..., -1:]
    return np.minimum((cumulative < uniforms[..., None]).sum(axis=-1), weights.shape[-1] - 1)


def _pick(particles: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """``particles`` (B, N, n) at ``indices`` (B, M) → (B, M, n)."""
    return np.take_along_axis(particles, indices[..., None], axis=1)


def ffbsi(
    clouds: Sequence[ParticleCloud],
    model: FilterModel,
    rngs: Sequence[np.random.Generator],
    trajectories: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed means (K, B, n) and covariances (K, B, n, n) from the clouds of K steps, with
    ``trajectories`` (M) backward draws per run, run ``b`` drawing from ``rngs[b]``."""
    if isinstance(trajectories, bool) or not isinstance(trajectories, int | np.integer) or trajectories < 1:
        raise ValueError(f"trajectories must be an integer >= 1, got {trajectories!r}")
    K = len(clouds)
    B, _, n = clouds[-1].particles.shape
    M = int(trajectories)

    last = clouds[-1]
    final_weights = np.broadcast_to(last.weights[:, None, :], (B, M, last.weights.shape[1]))
    drawn = _pick(last.particles, _categorical(final_weights, draw_uniforms("multinomial", rngs, M)))
    means = np.empty((K, B, n))
    covs = np.empty((K, B, n, n))
    for k in range(K - 1, -1, -1):
        if k < K - 1:
            cloud, u_next = clouds[k], clouds[k + 1].input
            predicted = model.f(cloud.particles, u_next)  # (B, N, n)
            log_transition = model.process_noise_logpdf(drawn[:, :, None, :] - predicted[:, None, :, :])  # (B, M, N)
            with np.errstate(divide="ignore"):
                log_b = np.log(cloud.weights)[:, None, :] + log_transition
            lost = ~np.isfinite(log_b.max(axis=-1))  # no particle can reach this trajectory's next state
            if lost.any():  # it continues from the filter's weights alone
                log_b[lost] = np.log(np.broadcast_to(cloud.weights[:, None, :], log_b.shape)[lost])
            log_b -= log_b.max(axis=-1, keepdims=True)
            drawn = _pick(cloud.particles, _categorical(np.exp(log_b), draw_uniforms("multinomial", rngs, M)))
        means[k] = drawn.mean(axis=1)
        d = drawn - means[k][:, None, :]
        covs[k] = np.einsum("bmi,bmj->bij", d, d) / M
    return means, covs
