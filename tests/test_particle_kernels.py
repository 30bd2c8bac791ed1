"""The compiled particle-filter kernels (:mod:`quadest.numerics.particle_kernels`, the UNGM model's
:mod:`quadest.models.validation_kernels`) against their numpy references.

Tolerance 0 everywhere, and why that is the right one: every kernel performs its reference's IEEE
operations in the same order (a sequential ``cumsum``, numpy's pairwise summation reproduced block
for block, the same divisions, products and comparisons; numba contracts nothing to a fused
multiply-add without ``fastmath``), draws from the same generators in the same order, and leaves
``exp`` to numpy. A round-off tolerance would let a reordered sum or a reciprocal in place of a
division through; equality also keeps every checked-in particle-filter result unchanged.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from quadest.conformance import linear_gaussian_problem
from quadest.estimators.particle import BootstrapPF, gather_particles
from quadest.estimators.particle_ekpf import EKPF
from quadest.estimators.particle_ilopf import ILOPF
from quadest.estimators.particle_upf import UPF
from quadest.models.base import _gaussian_logpdf
from quadest.models.validation import UNGMModel
from quadest.numerics import particle_kernels
from quadest.numerics.draws import particle_kernels as active_kernels
from quadest.numerics.draws import standard_normals
from quadest.numerics.resampling import (
    RESAMPLING_SCHEMES,
    draw_uniforms,
    effective_sample_size,
    normalise_log_weights,
    normalised_weights,
    resample,
    resample_from_uniforms,
)


def generators(seeds) -> list[np.random.Generator]:
    return [np.random.default_rng(s) for s in seeds]


def numba(monkeypatch) -> None:
    monkeypatch.setenv("QUADEST_KERNELS", "numba")
    assert active_kernels() is particle_kernels


def numpy_backend(monkeypatch) -> None:
    monkeypatch.setenv("QUADEST_KERNELS", "numpy")
    assert active_kernels() is None


def spiky_weights(rng: np.random.Generator, B: int, N: int) -> np.ndarray:
    """Normalised weights of very different sizes, with exact zeros and one run on one particle."""
    w = rng.random((B, N)) ** 12
    w[:, rng.random(N) < 0.2] = 0.0
    w[0] = 0.0
    w[0, N // 2] = 1.0
    w[:, 0] += 1e-300 * (w.sum(axis=1) == 0)  # no all-zero run
    return w / w.sum(axis=1, keepdims=True)


@pytest.mark.parametrize("shape", [(7,), (1000, 1), (33, 3)])
def test_standard_normals_draw_what_each_generator_draws_alone(monkeypatch, shape):
    numba(monkeypatch)
    seeds = range(5)
    mine, alone = generators(seeds), generators(seeds)
    runs = np.array([4, 1, 3])
    out = standard_normals(mine, shape, runs)
    assert out.shape == (3, *shape)
    for row, b in zip(out, runs, strict=True):
        np.testing.assert_array_equal(row, alone[b].standard_normal(shape))
    for b in range(5):  # the generators end in the same state, drawn or not
        assert mine[b].random() == alone[b].random()


@pytest.mark.parametrize("scheme", RESAMPLING_SCHEMES)
@pytest.mark.parametrize("N", [1, 7, 8, 129, 1000])
def test_resampling_kernel_gives_the_reference_indices(monkeypatch, scheme, N):
    rng = np.random.default_rng(N)
    B = 6
    w = spiky_weights(rng, B, N) if N > 1 else np.ones((B, 1))
    runs = np.array([5, 0, 2, 3])
    numba(monkeypatch)
    mine = generators(range(B))
    compiled = resample(scheme, w[runs], mine, runs)
    reference_rngs = generators(range(B))
    uniforms = draw_uniforms(scheme, [reference_rngs[b] for b in runs], N)
    np.testing.assert_array_equal(compiled, resample_from_uniforms(scheme, w[runs], uniforms))
    for b in range(B):
        assert mine[b].random() == reference_rngs[b].random()


@pytest.mark.parametrize("scheme", RESAMPLING_SCHEMES)
def test_resampling_backends_agree_on_many_uniforms_near_the_cumulative_weights(monkeypatch, scheme):
    """Uniforms landing exactly on cumulative weights (equal weights, N a power of 2) are where a
    ``<`` for ``≤`` in the selection shows."""
    N, B = 64, 3
    w = np.full((B, N), 1.0 / N)  # cumulative weights (j + 1) / 64, exact
    if scheme in ("stratified", "systematic"):
        uniforms = np.zeros((B, N))  # positions i / 64: on the cumulative weights
    else:
        uniforms = np.tile(np.arange(N) / N, (B, 1))
    reference = resample_from_uniforms(scheme, w, uniforms)
    numba(monkeypatch)
    code = {"multinomial": 0, "systematic": 1, "stratified": 2, "residual": 3}[scheme]
    out = np.empty((B, N), dtype=np.intp)
    particle_kernels.resample_kernel(code, w, uniforms, out)
    np.testing.assert_array_equal(out, reference)


@pytest.mark.parametrize("trailing", [(1,), (3,), (2, 2)])
def test_gather_kernel_picks_the_same_particles_in_place(trailing):
    rng = np.random.default_rng(1)
    B, N = 5, 40
    particles = rng.standard_normal((B, N, *trailing))
    runs = np.array([3, 1])
    idx = rng.integers(0, N, (2, N))
    expected = particles.copy()
    expected[runs] = gather_particles(particles[runs], idx)
    fresh = np.zeros((B, N, int(np.prod(trailing))))
    particle_kernels.gather_kernel(particles.reshape(B, N, -1), runs, idx, fresh)
    np.testing.assert_array_equal(fresh[runs].reshape(2, N, *trailing), expected[runs])
    particle_kernels.gather_kernel(particles.reshape(B, N, -1), runs, idx, particles.reshape(B, N, -1))
    np.testing.assert_array_equal(particles, expected)


@pytest.mark.parametrize("spread", [30.0, 0.3])
@pytest.mark.parametrize("N", [1, 7, 8, 128, 129, 1000, 20000])
def test_normalised_weights_and_ess_equal_the_reference_bit_for_bit(monkeypatch, N, spread):
    """Sizes around numpy's pairwise-summation blocks (8 accumulators, blocks of 128), spiky
    weights (most underflow) and flat ones (where every term of the sums counts, so the order of
    the additions shows), and runs with NaN, ±inf and no finite log-weight at all."""
    rng = np.random.default_rng(N)
    B = 6
    log_w = np.log(rng.random((B, N)))
    incr = -0.5 * (spread * rng.standard_normal((B, N))) ** 2
    incr[1] = -np.inf
    incr[2, : max(1, N // 3)] = np.nan
    incr[3, -1] = np.inf
    incr[4] = np.nan
    w_ref, vanished_ref = normalise_log_weights(log_w + incr)
    numba(monkeypatch)
    w, vanished, ess = normalised_weights(log_w, incr)
    np.testing.assert_array_equal(w, w_ref)
    np.testing.assert_array_equal(vanished, vanished_ref)
    np.testing.assert_array_equal(ess, effective_sample_size(w_ref))
    assert vanished[1] and vanished[4] and not vanished[0]


@pytest.mark.parametrize("r", [1, 3, 9])
def test_diagonal_gaussian_log_density_kernel_equals_numpy(monkeypatch, r):
    rng = np.random.default_rng(r)
    C = np.diag(rng.uniform(0.01, 30.0, r))
    scale = np.sqrt(np.diag(C))
    e = 10.0 * rng.standard_normal((4, 50, r))
    numpy_backend(monkeypatch)
    reference = _gaussian_logpdf(e, C, scale)
    numba(monkeypatch)
    np.testing.assert_array_equal(_gaussian_logpdf(e, C, scale), reference)
    np.testing.assert_allclose(reference, _gaussian_logpdf(e, C), rtol=1e-13)  # the Cholesky path: same density


def test_ungm_compiled_f_and_h_equal_the_numpy_reference(monkeypatch):
    numba(monkeypatch)
    rng = np.random.default_rng(2)
    model = UNGMModel(Q=10.0, R=1.0, dt=1.0, batch_size=4)
    x = 30.0 * rng.standard_normal((4, 257, 1))
    u = np.array([[0.0], [1.0], [57.0], [499.0]])
    np.testing.assert_array_equal(model.f(x, u), model.f_numpy(x, u))
    np.testing.assert_array_equal(model.h(x, u), model.h_numpy(x, u))
    numpy_backend(monkeypatch)
    assert model._compiled(x) is None


OPTIONS = [
    {"resampling": "stratified", "estimate": "resampled"},
    {"resampling": "residual", "schedule": "ess", "roughening": 0.2},
    {"resampling": "multinomial", "weights": "linear_floor"},
    {"resampling": "systematic", "initial_cloud": "uniform", "initial_range": [-3.0, 3.0]},
]


def _filter(cls, options, steps: int = 12):
    model, x0, P0, u, z = linear_gaussian_problem(runs=4, steps=steps)
    est = cls(model, particles=96, **options)
    est.set_generators(generators([7, 8, 9, 10]))
    est.initialize(x0.copy(), P0.copy())
    means, covs = [], []
    for k in range(1, steps + 1):
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        means.append(est.mean.copy())
        covs.append(est.covariance.copy())
    return np.array(means), np.array(covs), est.diagnostics()


@pytest.mark.parametrize("cls", [BootstrapPF, EKPF, ILOPF, UPF])
@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: o["resampling"])
def test_every_particle_filter_gives_the_same_numbers_on_both_backends(monkeypatch, cls, options):
    numpy_backend(monkeypatch)
    reference = _filter(cls, options)
    numba(monkeypatch)
    compiled = _filter(cls, options)
    np.testing.assert_array_equal(compiled[0], reference[0])
    np.testing.assert_array_equal(compiled[1], reference[1])
    for key, value in reference[2].items():
        np.testing.assert_array_equal(compiled[2][key], value, err_msg=key)


def _ungm_filter(cls, steps: int = 15):
    """The UNGM benchmark (scalar, diagonal noise: the compiled log-density and f/h paths)."""
    rng = np.random.default_rng(4)
    model = UNGMModel(Q=10.0, R=1.0, dt=1.0, batch_size=3)
    u = np.arange(steps + 1.0)[None, :, None].repeat(3, axis=0)
    x = np.zeros((3, 1, 1))
    z = np.zeros((3, steps + 1, 1))
    for k in range(1, steps + 1):
        x = model.f_numpy(x, u[:, k - 1]) + np.sqrt(10.0) * rng.standard_normal((3, 1, 1))
        z[:, k] = (model.h_numpy(x, u[:, k]) + rng.standard_normal((3, 1, 1)))[:, 0]
    est = cls(model, particles=200, resampling="systematic")
    est.set_generators(generators([1, 2, 3]))
    est.initialize(np.full((3, 1), 0.1), np.ones((3, 1, 1)))
    means = []
    for k in range(1, steps + 1):
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        means.append(est.mean.copy())
    return np.array(means)


@pytest.mark.parametrize("cls", [BootstrapPF, EKPF])
def test_particle_filters_on_ungm_give_the_same_numbers_on_both_backends(monkeypatch, cls):
    numpy_backend(monkeypatch)
    reference = _ungm_filter(cls)
    numba(monkeypatch)
    np.testing.assert_array_equal(_ungm_filter(cls), reference)


@pytest.mark.integration
def test_constructing_a_particle_filter_loads_every_particle_kernel_before_any_timed_call():
    """The runner times ``initialize`` and every step, so the kernels (and numba's typed list of
    generators) must be loaded when the filter is built; checked in a fresh process, where no
    earlier test has loaded them."""
    script = (
        "from quadest.estimators.particle import BootstrapPF\n"
        "from quadest.models.validation import UNGMModel\n"
        "from quadest.numerics import particle_kernels as k\n"
        "BootstrapPF(UNGMModel(1.0, 1.0, 1.0, 2), particles=8)\n"
        "names = ['standard_normal_kernel', 'resample_kernel', 'gather_kernel', "
        "'gaussian_logpdf_diagonal_kernel', 'shift_log_weights_kernel', 'normalise_kernel']\n"
        "print(sorted(n for n in names if not getattr(k, n).signatures))\n"
    )
    env = {**os.environ, "QUADEST_KERNELS": "numba"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.strip() == "[]", out.stdout
