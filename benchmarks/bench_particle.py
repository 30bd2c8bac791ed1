"""Benchmark the batched bootstrap particle filter on UNGM against a per-run loop over filterpy.

Run: ``python benchmarks/bench_particle.py`` (add ``--json`` for a machine-readable last line).

Everything is measured in the same run, on the same data (``experiment=ungm_toolbox``: Q = R = 1,
100 runs; 1000 particles per run, initial cloud N(0.1, 1), stratified resampling every step). The
filters' kernels are loaded (or compiled) before any timing:

1. ns per particle per step of quadest's ``pf`` for the whole batch of 100 runs × 1000 particles,
   in its exact mode (the default) and with ``kernel: fast`` (the fused step of
   ``quadest.numerics.fast_bootstrap``, numbers within Monte Carlo error of exact);
2. the same for a per-run loop: numpy propagation and weighting per run and
   ``filterpy.monte_carlo.stratified_resample`` (a Python loop over the particles; it draws from
   numpy's global generator, seeded here, because filterpy offers no other way);
3. the wall time of the runner on the full experiment (100 runs × 1000 particles × 500 steps),
   against the target of under 60 s for it.

4. the same ``pf`` on the numpy references (``QUADEST_KERNELS=numpy``), each compiled particle
   kernel against its numpy reference (µs per call for the batch, and compiled ÷ numpy), and the
   first-call compile time of the particle kernels and their cached load time (fresh processes
   with an empty numba cache directory of their own);
5. the ``particles`` library's bootstrap filter (Chopin; ``particles_ungm.py``) on the same
   measurements, per run, stratified resampling every step. ``particles`` 0.4 pins numpy < 2 and
   must never enter quadest's dependencies, so it runs in a separate environment whose Python is
   given by ``--particles-python`` (or ``QUADEST_PARTICLES_PYTHON``)::

       python -m venv /tmp/particles-env && /tmp/particles-env/bin/pip install particles==0.4
       python benchmarks/bench_particle.py --particles-python /tmp/particles-env/bin/python

   Without it the script prints a note and skips this column.

Items 1 and 2 are the median over the timed steps of each step's CPU time of the process
(``time.process_time``; item 5 the CPU time of all runs), the same as wall time for this
single-threaded code on an idle machine and less sensitive to other processes on a shared one.
The ratios are measured in the same run, so load that remains (caches, memory bandwidth) acts on
both sides. The runner's time (3) and the compile times (4) are wall time.

``--quick`` runs every stage at toy sizes (4 runs × 50 particles, 3 steps, one timing repeat, the
compile script on the existing numba cache): what the test suite runs so that a broken script
fails it (tests/test_benchmarks_quick.py). Its numbers mean nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from filterpy.monte_carlo import stratified_resample
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from measure import best_us, fresh_process_runs
from quadest.app.schema import register_schemas
from quadest.app.settings import data_settings
from quadest.config.paths import config_dir
from quadest.estimators.particle import BootstrapPF, gather_particles
from quadest.models.base import _gaussian_logpdf
from quadest.numerics import particle_kernels, square_root
from quadest.numerics.draws import standard_normals
from quadest.numerics.resampling import RESAMPLING_SCHEMES, normalised_weights, resample_from_uniforms
from quadest.runner import run_estimator
from quadest.simulation.validation_data import build_ungm_data

PARTICLES = 1000
RUNS = 100


def ungm_data(runs: int):
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ungm_toolbox", f"runs={runs}"])
    return build_ungm_data(data_settings(cfg))


def batched_pf(data, particles: int, kernel: str = "exact") -> BootstrapPF:
    est = BootstrapPF(data.model, particles=particles, resampling="stratified", estimate="resampled", kernel=kernel)
    est.set_generators([np.random.default_rng(s) for s in data.estimator_seeds])
    B, n = data.x0.shape
    est.initialize(data.x0, np.broadcast_to(data.P0, (B, n, n)).copy())
    return est


def time_batched(data, steps: int, particles: int = PARTICLES, kernel: str = "exact") -> float:
    """ns per particle per step of quadest's pf (``kernel``: exact or fast) over the whole batch,
    after two untimed steps (which load the compiled kernels)."""
    est = batched_pf(data, particles, kernel)
    for k in range(1, 3):
        est.predict(data.inputs[:, k - 1])
        est.update(data.measurements[:, k], data.inputs[:, k])
    times = []
    for k in range(3, steps + 3):
        start = time.process_time()
        est.predict(data.inputs[:, k - 1])
        est.update(data.measurements[:, k], data.inputs[:, k])
        times.append(time.process_time() - start)
    return float(np.median(times)) / (data.x0.shape[0] * particles) * 1e9


def on_backend(backend: str, fun: Callable[[], float]) -> float:
    """``fun()`` with ``QUADEST_KERNELS=backend``."""
    before = os.environ.get(square_root.KERNELS_ENV)
    os.environ[square_root.KERNELS_ENV] = backend
    try:
        return fun()
    finally:
        os.environ.pop(square_root.KERNELS_ENV)
        if before is not None:
            os.environ[square_root.KERNELS_ENV] = before


def kernel_ratios(B: int = RUNS, N: int = PARTICLES, repeats: int = 20, blocks: int = 5) -> dict[str, dict[str, float]]:
    """Each compiled particle kernel against its numpy reference on the benchmark's sizes: µs per
    call for the batch on each backend and compiled ÷ numpy (the resampling from given uniforms)."""
    rng = np.random.default_rng(0)
    w = rng.random((B, N)) ** 4
    w /= w.sum(axis=1, keepdims=True)
    uniforms, idx = rng.random((B, N)), rng.integers(0, N, (B, N))
    log_w, incr = np.log(w), -0.5 * rng.standard_normal((B, N)) ** 2
    x, runs = rng.standard_normal((B, N, 1)), np.arange(B)
    R = np.eye(1)
    model = ungm_data(2).model
    u = np.arange(B, dtype=float)[:, None]
    codes = {"multinomial": 0, "systematic": 1, "stratified": 2, "residual": 3}
    out = np.empty((B, N), dtype=np.intp)
    pairs: dict[str, tuple[Callable[[], object], Callable[[], object]]] = {
        "standard_normals": (
            lambda: standard_normals(rngs, (N, 1)),
            lambda: [rng_b.standard_normal((N, 1)) for rng_b in rngs],
        ),
        "normalised_weights": (lambda: normalised_weights(log_w, incr), lambda: normalised_weights(log_w, incr)),
        "gaussian_logpdf": (lambda: _gaussian_logpdf(x, R, np.ones(1)), lambda: _gaussian_logpdf(x, R, np.ones(1))),
        "gather": (
            lambda: particle_kernels.gather_kernel(x, runs, idx, np.empty_like(x)),
            lambda: gather_particles(x, idx),
        ),
        "ungm_f": (lambda: model.f(x, u), lambda: model.f_numpy(x, u)),
        "ungm_h": (lambda: model.h(x, u), lambda: model.h_numpy(x, u)),
    }
    for scheme in RESAMPLING_SCHEMES:
        pairs[f"resample_{scheme}"] = (
            lambda s=scheme: particle_kernels.resample_kernel(codes[s], w, uniforms, out),
            lambda s=scheme: resample_from_uniforms(s, w, uniforms),
        )
    rngs = [np.random.default_rng(s) for s in range(B)]
    result = {}
    for name, (compiled, reference) in pairs.items():
        numba_us = on_backend("numba", lambda f=compiled: best_us(f, repeats, blocks))
        numpy_us = on_backend("numpy", lambda f=reference: best_us(f, repeats, blocks))
        result[name] = {
            "numba_us": round(numba_us, 1),
            "numpy_us": round(numpy_us, 1),
            "compiled_over_numpy": round(numba_us / numpy_us, 3),
        }
    return result


COMPILE_SCRIPT = """
import json, time
import numpy as np
start = time.perf_counter()
from quadest.estimators.particle import BootstrapPF
from quadest.models.validation import UNGMModel
imported = time.perf_counter()
model = UNGMModel(1.0, 1.0, 1.0, 2)
for scheme, kernel in [(s, "exact") for s in ("multinomial", "systematic", "stratified", "residual")] + [
    ("stratified", "fast")
]:
    est = BootstrapPF(model, particles=16, resampling=scheme, kernel=kernel)
    est.set_generators([np.random.default_rng(s) for s in range(2)])
    est.initialize(np.zeros((2, 1)), np.ones((2, 1, 1)))
    est.predict(np.zeros((2, 1)))
    est.update(np.zeros((2, 1)), np.ones((2, 1)))
print(json.dumps({"import_s": imported - start, "first_calls_s": time.perf_counter() - imported}))
"""


def compile_times(fresh_cache: bool = True) -> dict[str, float]:
    """The first steps of ``pf`` with each resampling scheme in a fresh process with an empty numba
    cache (the particle kernels and the UNGM f/h compile), then in a second fresh process with that
    cache (they load); ``fresh_cache=False``: both on the existing cache."""
    runs = fresh_process_runs(COMPILE_SCRIPT, fresh_cache)
    return {"compile_s": round(runs[0]["first_calls_s"], 2), "cached_load_s": round(runs[1]["first_calls_s"], 2)}


def time_filterpy_loop(data, steps: int, particles: int = PARTICLES) -> float:
    """ns per particle per step of a per-run bootstrap filter resampling with filterpy."""
    model = data.model
    q, r = float(np.sqrt(model.Q[0, 0])), float(model.R[0, 0])
    np.random.seed(0)
    rng = np.random.default_rng(0)
    B = data.x0.shape[0]
    clouds = [data.x0[i, 0] + np.sqrt(data.P0[0, 0]) * rng.standard_normal(particles) for i in range(B)]
    times = []
    for k in range(1, steps + 1):
        start = time.process_time()
        for i in range(B):
            x = clouds[i]
            x = 0.5 * x + 25.0 * x / (1.0 + x * x) + 8.0 * np.cos(1.2 * data.inputs[i, k - 1, 0])
            x = x + q * rng.standard_normal(particles)
            w = np.exp(-0.5 * (data.measurements[i, k, 0] - x * x / 20.0) ** 2 / r)
            w /= w.sum()
            clouds[i] = x[stratified_resample(w)]
        times.append(time.process_time() - start)
    return float(np.median(times)) / (B * particles) * 1e9


def time_full_experiment(data, particles: int = PARTICLES) -> float:
    """Wall time in s of the runner with pf on the whole experiment."""
    est = BootstrapPF(data.model, particles=particles, resampling="stratified", estimate="resampled")
    start = time.perf_counter()
    run_estimator("pf", est, data, divergence_bound=1e6)
    return time.perf_counter() - start


def time_particles_library(python: str, data, steps: int, particles: int = PARTICLES) -> dict:
    """Run ``particles_ungm.py`` with ``python`` on the first ``steps`` measurements of every run."""
    with tempfile.TemporaryDirectory() as tmp:
        measurements = Path(tmp) / "measurements.npy"
        np.save(measurements, data.measurements[:, 1 : steps + 1, 0])
        script = Path(__file__).with_name("particles_ungm.py")
        out = subprocess.run(
            [python, str(script), str(measurements), str(particles)], capture_output=True, text=True, check=True
        )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print a JSON summary as the last line")
    parser.add_argument("--steps", type=int, default=50, help="steps timed for the batched filter")
    parser.add_argument("--loop-steps", type=int, default=10, help="steps timed for the filterpy loop")
    parser.add_argument(
        "--particles-python",
        default=os.environ.get("QUADEST_PARTICLES_PYTHON"),
        help="Python of a separate environment with particles 0.4 installed (default: $QUADEST_PARTICLES_PYTHON)",
    )
    parser.add_argument("--quick", action="store_true", help="every stage at toy sizes, numbers meaningless (tests)")
    args = parser.parse_args()
    runs, N = (4, 50) if args.quick else (RUNS, PARTICLES)
    steps, loop_steps = (3, 2) if args.quick else (args.steps, args.loop_steps)
    timing = {"repeats": 1, "blocks": 1} if args.quick else {}
    load_before = os.getloadavg()[0]
    data = ungm_data(runs)
    batched = on_backend("numba", lambda: time_batched(data, steps, N))
    fast = on_backend("numba", lambda: time_batched(data, steps, N, "fast"))
    batched_numpy = on_backend("numpy", lambda: time_batched(data, steps, N))
    loop = time_filterpy_loop(data, loop_steps, N)
    full = time_full_experiment(data, N)
    ratios = kernel_ratios(runs, N, **timing)
    compile_s = compile_times(fresh_cache=not args.quick)
    library = time_particles_library(args.particles_python, data, steps, N) if args.particles_python else None
    print(f"pf, {runs} runs x {N} particles: {batched:.1f} ns per particle per step (compiled kernels)")
    print(f"pf kernel=fast (fused step, within Monte Carlo error of exact): {fast:.1f} ns per particle per step")
    print(f"pf on the numpy references (QUADEST_KERNELS=numpy): {batched_numpy:.1f} ns per particle per step")
    print(f"per-run loop with filterpy.stratified_resample: {loop:.1f} ns per particle per step")
    print(
        f"speed-up: exact {loop / batched:.1f}x, fast {loop / fast:.1f}x "
        f"(goal 20x; numpy references: {loop / batched_numpy:.1f}x)"
    )
    print(f"compiled particle kernels against their numpy references ({runs} runs x {N} particles, µs per call):")
    for name, r in ratios.items():
        ratio = r["compiled_over_numpy"]
        print(f"  {name:22s} {r['numba_us']:8.1f} vs {r['numpy_us']:8.1f}  compiled / numpy = {ratio:.3f}")
    print(
        f"first steps of pf with every scheme and kernel: {compile_s['compile_s']:.2f} s compiling the kernels "
        f"(empty cache), {compile_s['cached_load_s']:.2f} s loading them from the cache"
    )
    print(f"runner, ungm_toolbox with pf ({runs} runs x {N} particles x 500 steps): {full:.1f} s")
    load = (load_before, os.getloadavg()[0])
    print(f"1-minute load average before / after: {load[0]:.1f} / {load[1]:.1f} on {os.cpu_count()} cores")
    if library is None:
        print(
            "particles library: skipped (particles 0.4 pins numpy < 2, so it is not a quadest dependency; "
            "give --particles-python, see this script's docstring)"
        )
    else:
        print(
            f"particles {library['particles_version']} bootstrap filter (numpy {library['numpy_version']}, separate "
            f"environment, per run): {library['ns_per_particle_step']:.1f} ns per particle per step; "
            f"pf is {library['ns_per_particle_step'] / batched:.1f}x faster (fast: "
            f"{library['ns_per_particle_step'] / fast:.1f}x)"
        )
    if args.json:
        summary = {
            "pf_ns_per_particle_step": round(batched, 2),
            "filterpy_loop_ns_per_particle_step": round(loop, 2),
            "speedup": round(loop / batched, 1),
            "pf_fast_ns_per_particle_step": round(fast, 2),
            "speedup_fast": round(loop / fast, 1),
            "ungm_toolbox_pf_s": round(full, 1),
            "load_average": [round(v, 2) for v in load],
            "particles_library_ns_per_particle_step": library and round(library["ns_per_particle_step"], 2),
            "pf_numpy_ns_per_particle_step": round(batched_numpy, 2),
            "speedup_numpy_kernels": round(loop / batched_numpy, 1),
            "kernel_ratios": ratios,
            **compile_s,
        }
        print(json.dumps(summary))


if __name__ == "__main__":
    main()
