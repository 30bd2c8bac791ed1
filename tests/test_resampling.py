"""Resampling schemes: filterpy's indices on the same uniforms, unbiasedness, batch = alone, ESS."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.monte_carlo import resampling as fp

from quadest.errors import ConfigError
from quadest.numerics.resampling import (
    BLOCK_PARTICLES,
    RESAMPLING_SCHEMES,
    draw_uniforms,
    effective_sample_size,
    normalise_log_weights,
    resample,
    resample_from_uniforms,
)


def _weights(rng: np.random.Generator, B: int, N: int) -> np.ndarray:
    """Skewed weights with some exact zeros and some particles worth several copies."""
    w = rng.gamma(0.3, size=(B, N))
    w[:, ::7] = 0.0
    return w / w.sum(axis=1, keepdims=True)


def _filterpy_indices(scheme: str, w: np.ndarray, u: np.ndarray, monkeypatch) -> np.ndarray:
    """filterpy's indices for one run with its global ``random`` replaced by our uniforms."""
    N = len(w)
    if scheme == "systematic":
        monkeypatch.setattr(fp, "random", lambda: u[0])
        return fp.systematic_resample(w)
    if scheme == "stratified":
        monkeypatch.setattr(fp, "random", lambda size: u[:size])
        return fp.stratified_resample(w)
    if scheme == "multinomial":
        monkeypatch.setattr(fp, "random", lambda size: u[:size])
        return fp.multinomial_resample(w)
    # residual: filterpy's deterministic copies (right), then filterpy's multinomial on the
    # residual weights N w - floor(N w) (filterpy issue #290: its own residual weights are wrong)
    copies = np.floor(N * w)
    kept = int(copies.sum())
    fixed = fp.residual_resample(w)[:kept]
    monkeypatch.setattr(fp, "random", lambda size: u[:size])
    residual = N * w - copies
    return np.concatenate([fixed, fp.multinomial_resample(residual / residual.sum())[: N - kept]])


@pytest.mark.parametrize("scheme", RESAMPLING_SCHEMES)
def test_same_indices_as_filterpy_on_the_same_uniforms(scheme, monkeypatch):
    rng = np.random.default_rng(7)
    B, N = 6, 50
    w = _weights(rng, B, N)
    u = rng.random((B, N))
    ours = resample_from_uniforms(scheme, w, u)
    for b in range(B):
        np.testing.assert_array_equal(ours[b], _filterpy_indices(scheme, w[b], u[b], monkeypatch))


@pytest.mark.parametrize("scheme", ["stratified", "systematic"])
@pytest.mark.parametrize("u", [0.0, 0.5])
def test_positions_on_the_cumulative_weights_select_as_filterpy(scheme, u, monkeypatch):
    """Dyadic weights have exact cumulative sums k/8, and uniforms 0 or 1/2 put positions exactly on
    them: ties, where only the rule ``c_j ≤ u`` (filterpy's ``u < c_j`` moves on) decides."""
    w = np.array([[2.0, 0.0, 1.0, 0.0, 3.0, 1.0, 0.0, 1.0], [0.0, 0.0, 0.0, 4.0, 4.0, 0.0, 0.0, 0.0]]) / 8.0
    uniforms = np.full((2, 8), u)
    ours = resample_from_uniforms(scheme, w, uniforms)
    for b in range(2):
        np.testing.assert_array_equal(ours[b], _filterpy_indices(scheme, w[b], uniforms[b], monkeypatch))


@pytest.mark.parametrize("scheme", ["stratified", "systematic"])
def test_strata_selection_follows_the_rule_across_blocks_and_at_the_edges(scheme):
    """The linear-time selection against the rule itself, ``min(#{j : c_j ≤ u_i}, N − 1)`` by brute
    force, over more runs than one block holds, with zero weights, positions placed on cumulative
    weights (ties) and a uniform so close to 1 that ``i + u`` rounds to ``i + 1`` (the last position
    to exactly 1)."""
    rng = np.random.default_rng(5)
    N = 1000
    B = 2 * BLOCK_PARTICLES // N + 3
    w = _weights(rng, B, N)
    w[1, :990] = 0.0  # all weight on a few particles
    w[3] = 1.0  # c_j = fl((j + 1)/N) = u_j of a uniform that rounds up: a tie one stratum below ⌊N c_j⌋
    w /= w.sum(axis=1, keepdims=True)
    c = np.cumsum(w, axis=1)
    c /= c[:, -1:]
    u = rng.random((B, N))
    i = np.floor(c[2] * N).astype(int).clip(0, N - 1)
    u[2, i] = c[2] * N - i  # position i on c_j
    u[3] = 1.0 - 2.0**-53  # (N − 1 + u) / N rounds to 1
    positions = (np.arange(N) + (u if scheme == "stratified" else u[:, :1])) / N
    rule = np.minimum((c[:, None, :] <= positions[:, :, None]).sum(axis=-1), N - 1)
    np.testing.assert_array_equal(resample_from_uniforms(scheme, w, u), rule)
    assert positions[3, -1] == 1.0 and (positions[3, :-1] == c[3, :-1]).sum() > 100
    if scheme == "stratified":  # (systematic reads u[:, 0] only)
        assert (positions[2, i] == c[2]).sum() > 100


@pytest.mark.parametrize("scheme", RESAMPLING_SCHEMES)
def test_unbiased_expected_copies(scheme):
    """E[copies_i] = N w_i. Each draw gives counts with Var(copies_i) ≤ N w_i (1 − w_i) (the
    multinomial variance; the other schemes have less, Douc et al. 2005), so the mean over M
    independent draws is within 5 standard errors √(N wᵢ(1 − wᵢ)/M) with probability > 1 − 1e-5
    per particle (a 5-sigma band for N particles: family-wise false-alarm rate < 1e-4)."""
    rng = np.random.default_rng(11)
    N, M = 20, 20000
    w = _weights(rng, 1, N)[0]
    u = rng.random((M, N))
    idx = resample_from_uniforms(scheme, np.broadcast_to(w, (M, N)), u)
    counts = np.apply_along_axis(np.bincount, 1, idx, minlength=N)
    assert (counts.sum(axis=1) == N).all()
    se = np.sqrt(N * w * (1 - w) / M)
    np.testing.assert_array_less(np.abs(counts.mean(axis=0) - N * w), 5 * se + 1e-12)


@pytest.mark.parametrize("scheme", RESAMPLING_SCHEMES)
@pytest.mark.slow
def test_batch_equals_alone_and_same_seed_same_indices(scheme):
    rng = np.random.default_rng(3)
    w = _weights(rng, 4, 30)
    batch = resample(scheme, w, [np.random.default_rng(s) for s in range(4)])
    for b in range(4):
        alone = resample(scheme, w[b : b + 1], [np.random.default_rng(b)])
        np.testing.assert_array_equal(batch[b], alone[0])


def test_deterministic_residual_needs_no_uniforms():
    """Weights that are multiples of 1/N give exactly N w_i copies whatever the uniforms."""
    w = np.array([[0.5, 0.25, 0.0, 0.25]])
    idx = resample_from_uniforms("residual", w, np.full((1, 4), 0.999))
    np.testing.assert_array_equal(idx[0], [0, 0, 1, 3])


def test_systematic_reads_one_uniform_per_run():
    u = draw_uniforms("systematic", [np.random.default_rng(0), np.random.default_rng(1)], 5)
    assert (u[:, 1:] == 0).all() and u[0, 0] == np.random.default_rng(0).random()


def test_ess_and_log_weight_normalisation():
    logw = np.array([[0.0, 0.0, np.log(2.0)], [0.0, -np.inf, -np.inf], [-np.inf, -np.inf, -np.inf]]) - 800.0
    w, vanished = normalise_log_weights(logw)
    np.testing.assert_allclose(w[0], [0.25, 0.25, 0.5])
    np.testing.assert_array_equal(vanished, [False, False, True])
    np.testing.assert_allclose(effective_sample_size(w[:2]), [1 / (2 * 0.25**2 + 0.5**2), 1.0])


def test_unknown_scheme_is_a_config_error():
    with pytest.raises(ConfigError, match="resampling"):
        resample("roulete", np.ones((1, 2)) / 2, [np.random.default_rng(0)])
