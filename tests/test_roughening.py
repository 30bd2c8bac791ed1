"""Roughening against its formula, for every registered particle filter.

Gordon, Salmond & Smith (1993), §4 ("roughening"): after resampling, every particle gets an
independent jitter ``N(0, σ_j²)`` in each coordinate j, with ``σ_j = K E_j N^(−1/n)``: ``K`` the
tuning constant (``roughening``), ``E_j`` the interval between the largest and smallest value of
coordinate j in the resampled cloud, ``N`` the number of particles and ``n`` the state dimension.
(Not the kernel-density bandwidth exponent ``N^(−1/(n+4))`` of the regularised particle filter.)

The test resamples a cloud of known spread per coordinate and run, and compares the empirical
jitter with that formula within its Monte Carlo error: with jitters ``σ ε_i``, ``ε_i`` iid
N(0, 1), ``Σ_i (σ ε_i)² / σ² ~ χ²(N)`` and ``Σ_i σ ε_i / (σ √N) ~ N(0, 1)``. Each check accepts its
central ``1 − α`` interval with ``α`` = 0.1 % divided by the number of checks (Bonferroni), so a
correct filter fails this test with probability below 0.1 %. With N = 2000 particles in n = 4
dimensions and 3 runs (24 checks) the interval allows σ between 0.936 and 1.065 times the formula
(scipy's χ² quantiles), and the bandwidth exponent would give σ 2000^(1/8) = 2.59 times too large.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2, norm

from helpers import compose_settings
from quadest.estimators.particle import ParticleFilter
from quadest.estimators.registry import build_estimator, builtin_estimators
from quadest.simulation.registry import build_data

PARTICLE_FILTERS = sorted(
    name
    for name, spec in builtin_estimators().items()
    if issubclass(spec.cls, ParticleFilter) and "roughening" in spec.params.__dataclass_fields__
)
N = 2000
K = 0.2
RUNS = 3
FAMILY_ALPHA = 1e-3


def test_every_particle_filter_is_checked():
    assert {"pf", "ekpf", "upf", "ilopf"} <= set(PARTICLE_FILTERS)


@pytest.mark.parametrize("name", PARTICLE_FILTERS)
def test_roughening_jitter_has_the_standard_deviation_of_gordon_salmond_and_smith(name):
    data = build_data(compose_settings(["model=linear", f"runs={RUNS}", "duration=0.1", "progress=false"]))
    model = data.model
    n = model.n
    est = build_estimator(name, {"kind": name, "particles": N, "roughening": K}, model)
    seeds = np.random.SeedSequence(20260505).spawn(RUNS + 1)
    est.set_generators([np.random.default_rng(s) for s in seeds[:RUNS]])
    est.initialize(data.x0, np.broadcast_to(data.P0, (RUNS, n, n)).copy())
    widths = np.outer(np.arange(1, RUNS + 1), 10.0 ** np.arange(-1, n - 1))  # (runs, n): 0.1 ... 100
    cloud = np.random.default_rng(seeds[RUNS]).random((RUNS, N, n)) - 0.5
    est.x = cloud * widths[:, None, :]

    resampled = {}
    redraw = est.redraw

    def recording_redraw(w, runs):
        redraw(w, runs)
        resampled["x"] = est.x[runs].copy()  # the resampled cloud, before any roughening

    est.redraw = recording_redraw
    runs = np.arange(RUNS)
    est.resample_runs(np.full((RUNS, N), 1.0 / N), runs)
    before = resampled["x"]
    jitter = est.x[runs] - before  # (runs, N, n)

    sigma = K * (before.max(axis=1) - before.min(axis=1)) * N ** (-1.0 / n)  # (runs, n)
    checks = 2 * sigma.size
    alpha = FAMILY_ALPHA / checks
    variance_ratio = np.sum(jitter**2, axis=1) / sigma**2  # ~ χ²(N) each
    lo, hi = chi2.ppf(alpha / 2, N), chi2.ppf(1 - alpha / 2, N)
    assert np.all((variance_ratio >= lo) & (variance_ratio <= hi)), (
        f"{name}: jitter std / (K E N^(-1/n)) = {np.sqrt(variance_ratio / N)}, allowed "
        f"[{np.sqrt(lo / N):.4f}, {np.sqrt(hi / N):.4f}]"
    )
    mean_z = np.sum(jitter, axis=1) / (sigma * np.sqrt(N))  # ~ N(0, 1) each
    assert np.all(np.abs(mean_z) <= norm.ppf(1 - alpha / 2)), f"{name}: jitter mean / (σ/√N) = {mean_z}"
