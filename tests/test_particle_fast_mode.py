"""The bootstrap filter's fast mode (``estimator.pf.kernel: fast``, quadest.numerics.fast_bootstrap).

Two claims, each tested so that it can fail:

- the compiled fast step gives its numpy reference's numbers to round-off on the same uniforms
  (the same ancestor indices, weights and moments within a few ulps times the number of terms
  summed: the kernels sum sequentially or reassociated, the reference pairwise, and libm's
  ``exp`` differs from numpy's in the last bit);
- the fast mode is the same filter as the exact mode: their mean RMSE on UNGM agrees within Monte
  Carlo error. Both modes draw the same normals and uniforms from each run's generator (common
  random numbers), so the per-run RMSE difference is paired; its mean must lie within the
  t interval built from the spread of those differences over the runs.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from quadest.errors import ConfigError
from quadest.estimators.params import parameter_problem
from quadest.estimators.particle import BootstrapPF, PFParams
from quadest.models.validation import UNGMModel
from quadest.numerics import particle_kernels
from quadest.numerics.draws import particle_kernels as active_kernels
from quadest.numerics.fast_bootstrap import (
    FAST_SCHEMES,
    draw_step_uniforms,
    fast_bootstrap_step,
    fast_bootstrap_step_reference,
    measurement_whitening,
)

EPS = np.finfo(float).eps


def use_backend(monkeypatch, backend: str) -> None:
    monkeypatch.setenv("QUADEST_KERNELS", backend)
    assert active_kernels() is (particle_kernels if backend == "numba" else None)


def step_inputs(rng: np.random.Generator, B: int, N: int, n: int, m: int):
    """Proposed particles, predicted measurements, measurements and previous log-weights with a
    full measurement covariance; run 0's likelihoods all vanish (``h = ∞``) and run 1 carries a
    NaN particle of zero weight; run 4 has five NaN likelihoods (zero weight)."""
    x = rng.standard_normal((B, N, n))
    hx = rng.standard_normal((B, N, m))
    z = rng.standard_normal((B, m))
    A = rng.standard_normal((m, m))
    R = A @ A.T + m * np.eye(m)
    log_w = 4.0 * np.log(rng.random((B, N)))  # ESS well below N/2: schedule ess resamples
    hx[0] = np.inf
    hx[4, :5] = np.nan
    x[1, 3], log_w[1, 3] = np.nan, -np.inf
    return x, hx, z, R, log_w


@pytest.mark.parametrize("scheme", FAST_SCHEMES)
@pytest.mark.parametrize("every_step", [True, False])
@pytest.mark.parametrize("estimate_resampled", [True, False])
@pytest.mark.parametrize("floor", [False, True])
def test_fast_step_kernels_give_the_reference_numbers_to_round_off(
    monkeypatch, scheme, every_step, estimate_resampled, floor
):
    use_backend(monkeypatch, "numba")
    rng = np.random.default_rng(7)
    B, N, n, m = 6, 300, 2, 2
    x, hx, z, R, log_w = step_inputs(rng, B, N, n, m)
    whitening, log_norm = measurement_whitening(R)
    uniforms = draw_step_uniforms(scheme, [np.random.default_rng(s) for s in range(B)], N)
    active = np.ones(B, dtype=bool)
    active[2] = False  # a failed run is never resampled
    log_floor = np.log(1e-2) if floor else np.log(1e-99)
    args = (
        x,
        hx,
        z,
        whitening,
        log_norm,
        log_w,
        uniforms,
        scheme,
        every_step,
        0.5,
        active,
        estimate_resampled,
        log_floor,
        floor,
    )
    fast, ref = fast_bootstrap_step(*args), fast_bootstrap_step_reference(*args)
    assert ref.vanished[0] != floor and not ref.vanished[1:].any()  # the floor keeps run 0's weights
    assert not ref.resampled[2] and ref.resampled[3:].any()
    for name in ("resampled", "vanished", "floored"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(ref, name), err_msg=name)
    np.testing.assert_array_equal(fast.x, ref.x)  # the same ancestors: a copy of the same particles
    tol = 8 * N * EPS  # a sum of N terms, each within a few ulps (exp, products), in another order
    np.testing.assert_allclose(fast.w, ref.w, rtol=tol, atol=0)
    np.testing.assert_allclose(fast.ess, ref.ess, rtol=tol)
    finite = np.isfinite(x).all(-1)
    scale = np.abs(np.where(finite[..., None], x, 0.0)).max()
    np.testing.assert_allclose(fast.mean, ref.mean, rtol=0, atol=tol * scale)
    np.testing.assert_allclose(fast.cov, ref.cov, rtol=0, atol=tol * scale**2)


def test_fast_step_uniforms_are_each_generators_own_draws(monkeypatch):
    """The compiled uniforms are numpy's ``random`` stream of each run's generator."""
    use_backend(monkeypatch, "numba")
    compiled = draw_step_uniforms("stratified", [np.random.default_rng(s) for s in range(3)], 50)
    use_backend(monkeypatch, "numpy")
    reference = draw_step_uniforms("stratified", [np.random.default_rng(s) for s in range(3)], 50)
    np.testing.assert_array_equal(compiled, reference)


def ungm_truth(runs: int, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """UNGM trajectories (runs, steps + 1, 1), measurements and inputs (the time index), Q = 10,
    R = 1 (Gordon et al. 1993's example), x₀ ~ N(0.1, 1)."""
    model = UNGMModel(10.0, 1.0, 1.0, runs)
    rng = np.random.default_rng(seed)
    u = np.broadcast_to(np.arange(steps + 1.0)[None, :, None], (runs, steps + 1, 1)).copy()
    x = np.empty((runs, steps + 1, 1))
    x[:, 0] = 0.1 + rng.standard_normal((runs, 1))
    for k in range(1, steps + 1):
        x[:, k] = model.f_numpy(x[:, k - 1, None], u[:, k - 1])[:, 0] + np.sqrt(10.0) * rng.standard_normal((runs, 1))
    z = model.h_numpy(x, u) + rng.standard_normal(x.shape)
    return x, z, u


def per_run_rmse(kernel: str, x: np.ndarray, z: np.ndarray, u: np.ndarray, particles: int) -> np.ndarray:
    runs, K1, _ = x.shape
    est = BootstrapPF(UNGMModel(10.0, 1.0, 1.0, runs), particles=particles, resampling="stratified", kernel=kernel)
    est.set_generators([np.random.default_rng([3, r]) for r in range(runs)])
    est.initialize(np.full((runs, 1), 0.1), np.ones((runs, 1, 1)))
    squared = np.zeros(runs)
    for k in range(1, K1):
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        squared += (est.mean[:, 0] - x[:, k, 0]) ** 2
    return np.sqrt(squared / (K1 - 1))


@pytest.mark.parametrize("backend", ["numba", "numpy"])
def test_fast_mode_rmse_agrees_with_exact_mode_within_monte_carlo_error(monkeypatch, backend):
    """Paired per-run RMSE differences over 200 runs; the fast and exact means must agree within
    the two-sided 99.9 % t interval of the mean difference (the tolerance is the runs' own spread)."""
    use_backend(monkeypatch, backend)
    x, z, u = ungm_truth(runs=200, steps=40, seed=11)
    exact = per_run_rmse("exact", x, z, u, particles=100)
    fast = per_run_rmse("fast", x, z, u, particles=100)
    d = fast - exact
    half_width = stats.t.ppf(0.9995, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size)
    assert abs(d.mean()) <= half_width, (d.mean(), half_width, exact.mean(), fast.mean())


def test_exact_is_the_default_kernel():
    assert PFParams().kernel == "exact"
    assert BootstrapPF(UNGMModel(1.0, 1.0, 1.0, 2), particles=8).kernel == "exact"


@pytest.mark.parametrize(
    ("options", "key"),
    [
        ({"kernel": "vectorised"}, "kernel"),
        ({"kernel": "fast", "resampling": "residual"}, "resampling"),
        ({"kernel": "fast", "roughening": 0.2}, "roughening"),
    ],
)
def test_unsupported_kernel_options_are_one_line_errors_before_any_work(options, key):
    problem = parameter_problem(PFParams, options, 1)
    assert problem is not None and problem[0] == key
    with pytest.raises(ConfigError) as info:
        BootstrapPF(UNGMModel(1.0, 1.0, 1.0, 2), particles=8, **options)
    assert info.value.key.endswith(key) and "\n" not in str(info.value)
