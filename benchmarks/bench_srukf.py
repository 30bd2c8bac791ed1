"""Benchmark the batched SR-UKF against filterpy's UKF on the thesis quadrotor filter model.

Run: ``python benchmarks/bench_srukf.py`` (add ``--json`` for a machine-readable last line).

Everything is measured in the same run, on the same data:

1. single-run step time (predict + update) of the SR-UKF and of filterpy 2.0's UKF, the latter
   both as filterpy is normally used (``fx``/``hx`` called once per sigma point) and with the
   sigma points evaluated in one vectorised call (what quadest's UKF baseline does), each calling
   the model written in numpy (the baseline of every earlier measurement, ``QUADEST_KERNELS=numpy``)
   and the model's compiled ``f``/``h``;
2. batched throughput of the SR-UKF in µs per filter step per run at B = 1, 10, 100, 1000, and
   the speed-up at B = 1000 over filterpy's UKF looped over runs (per-point use);
3. peak resident memory of a full 1000-run, 20 s, 100 Hz batch (truth, sensors and the
   SR-UKF with the runner's metrics), measured in a separate process;
4. the compiled square-root kernels (``QUADEST_KERNELS=numba``, docs/benchmarks.md) against their
   numpy references at B = 1000 on the thesis model's sizes, the SR-UKF on the numpy references
   (single run and B = 1000), the kernels with ``parallel=True`` over chunks of runs against the
   serial ones, and the first-call compile time and the cached load time of the kernels (each
   measured in fresh processes with an empty numba cache directory of their own).

The 1-minute load average is printed before and after: the machine may be shared.

``--quick`` runs every stage at toy sizes (B = 1 and 10, 5 steps, one timing repeat, a 10-run
memory child, the compile script once on the existing numba cache): what the test suite runs so
that a broken script fails it (tests/test_benchmarks_quick.py). Its numbers mean nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from numba import get_num_threads, njit, prange

from measure import best_us, fresh_process_runs
from quadest.app.schema import register_schemas
from quadest.app.settings import data_settings
from quadest.config.paths import config_dir
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.srukf import SRUKF
from quadest.numerics import compiled, square_root
from quadest.simulation.quadrotor_data import build_quadrotor_data

BATCHES = (1, 10, 100, 1000)
QUICK_BATCHES = (1, 10)


def config(overrides: list[str]):
    """The data settings of the default job with ``overrides``."""
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return data_settings(compose(config_name="config", overrides=overrides))


def filter_inputs(data):
    m = data.model
    return np.stack([m.filter_input(data.inputs[:, k], data.companion_truth[:, k]) for k in range(data.time.size)], 1)


def time_steps(est, data, u, steps: int) -> float:
    """Mean wall time of one predict + update for the whole batch, in µs."""
    B, n = data.x0.shape
    est.initialize(data.x0, np.broadcast_to(data.P0, (B, n, n)).copy())
    start = time.perf_counter()
    for k in range(1, steps + 1):
        est.predict(u[:, k - 1])
        est.update(data.measurements[:, k], u[:, k])
    return (time.perf_counter() - start) / steps * 1e6


def peak_memory_mb(runs: int, duration: float = 20.0) -> float:
    """Peak RSS of a child process that runs the full batch (``runs`` runs of ``duration`` s)
    through the runner."""
    script = f"""
import resource
from hydra import compose, initialize_config_dir
from quadest.config.paths import config_dir
from quadest.app.schema import register_schemas
from quadest.app.settings import data_settings
from quadest.estimators.srukf import SRUKF
from quadest.simulation.quadrotor_data import build_quadrotor_data
from quadest.runner import run_estimator
register_schemas()
with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
    cfg = compose(config_name="config", overrides=["runs={runs}", "duration={duration}"])
data = build_quadrotor_data(data_settings(cfg))
run_estimator("srukf", SRUKF(data.model, 0.5), data, 50.0, saved_runs=3)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0  # ru_maxrss is in KiB on Linux


def kernel_inputs(B: int, n: int = 6, m: int = 6) -> dict[str, tuple]:
    """The thesis model's sizes: the QR of 2n sigma columns and √Q (n × 3n), the W0 column, the
    posterior downdate by ``K Sy`` (n columns), the gain and the whitening of an m-vector."""
    rng = np.random.default_rng(0)
    A = rng.standard_normal((B, n, 3 * n))
    S = square_root.qr_factor_numpy(A)
    return {
        "qr": (A,),
        "cholupdate_1": (S, 0.3 * rng.standard_normal((B, n)), 0.5),
        "cholupdate_n": (S, 0.3 * S @ rng.standard_normal((B, n, n)) / n, -1.0),
        "kalman_gain": (rng.standard_normal((B, n, m)), S[:, :m, :m]),
        "whiten": (S[:, :m, :m], rng.standard_normal((B, m))),
    }


def kernel_ratios(B: int, repeats: int = 50, blocks: int = 5) -> dict[str, dict[str, float]]:
    """Each public function on both backends (µs per call for the batch) and compiled ÷ numpy."""
    functions = {
        "qr": square_root.qr_factor,
        "cholupdate_1": square_root.cholupdate,
        "cholupdate_n": square_root.cholupdate,
        "kalman_gain": square_root.kalman_gain,
        "whiten": square_root.whiten,
    }
    out = {}
    for name, args in kernel_inputs(B).items():
        times = {}
        for backend in ("numba", "numpy"):
            os.environ[square_root.KERNELS_ENV] = backend
            times[backend] = best_us(lambda f=functions[name], a=args: f(*a), repeats, blocks)
        out[name] = {
            "numba_us": round(times["numba"], 1),
            "numpy_us": round(times["numpy"], 1),
            "compiled_over_numpy": round(times["numba"] / times["numpy"], 3),
        }
    os.environ.pop(square_root.KERNELS_ENV)
    return out


@njit(parallel=True, cache=True)
def _qr_threads(A, out, chunks):
    B, n, L = A.shape
    for c in prange(chunks):
        compiled.qr_factor_runs(A, out, np.empty((n, L)), c * B // chunks, (c + 1) * B // chunks)


@njit(parallel=True, cache=True)
def _cholupdate_threads(S, X, scale, downdate, out, failed, chunks):
    B, n, _ = S.shape
    for c in prange(chunks):
        v = np.empty(n)
        compiled.cholupdate_runs(S, X, scale, downdate, out, failed, v, c * B // chunks, (c + 1) * B // chunks)


def kernel_threads(B: int, repeats: int = 50, blocks: int = 5) -> dict[str, dict[str, float]]:
    """The serial kernels against the same bodies run by ``prange`` over one chunk of runs per
    thread (``parallel=True``), µs per call for the batch."""
    inputs = kernel_inputs(B)
    A = inputs["qr"][0]
    S, U, _ = inputs["cholupdate_n"]
    out, failed, threads = np.empty_like(S), np.zeros(B, dtype=bool), get_num_threads()
    pairs = {
        "qr": (lambda: compiled.qr_factor_kernel(A, out), lambda: _qr_threads(A, out, threads)),
        "cholupdate_n": (
            lambda: compiled.cholupdate_kernel(S, U, 1.0, True, out, failed),
            lambda: _cholupdate_threads(S, U, 1.0, True, out, failed, threads),
        ),
    }
    return {
        name: {
            "serial_us": round(best_us(serial, repeats, blocks), 1),
            "parallel_us": round(best_us(parallel, repeats, blocks), 1),
            "threads": threads,
        }
        for name, (serial, parallel) in pairs.items()
    }


COMPILE_SCRIPT = """
import json, time
import numpy as np
start = time.perf_counter()
import numba
from quadest.numerics import compiled, square_root
imported = time.perf_counter()
rng = np.random.default_rng(0)
A = rng.standard_normal((2, 6, 18))
S = square_root.qr_factor(A)
square_root.cholupdate(S, 0.1 * S, -1.0)
square_root.kalman_gain(A[:, :, :6], S)
square_root.whiten(S, A[:, :, 0])
print(json.dumps({"import_s": imported - start, "first_calls_s": time.perf_counter() - imported}))
"""


def compile_times(fresh_cache: bool = True) -> dict[str, float]:
    """First calls of the four kernels in a fresh process with an empty numba cache (they compile),
    then in a second fresh process with that cache (they load), and numba's import time
    (``fresh_cache=False``: both processes on the existing cache)."""
    runs = fresh_process_runs(COMPILE_SCRIPT, fresh_cache)
    return {
        "compile_s": round(runs[0]["first_calls_s"], 3),
        "cached_load_s": round(runs[1]["first_calls_s"], 3),
        "numba_import_s": round(runs[1]["import_s"], 3),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="end with one JSON line of the results")
    parser.add_argument("--steps", type=int, default=200, help="filter steps timed per measurement")
    parser.add_argument("--skip-memory", action="store_true", help="skip the 1000-run memory measurement")
    parser.add_argument("--skip-compile", action="store_true", help="skip the compile-time measurement")
    parser.add_argument("--quick", action="store_true", help="every stage at toy sizes, numbers meaningless (tests)")
    args = parser.parse_args()
    steps = 5 if args.quick else args.steps
    batches = QUICK_BATCHES if args.quick else BATCHES
    big = max(batches)
    timing = {"repeats": 1, "blocks": 1} if args.quick else {}
    load_start = os.getloadavg()[0]
    print(f"load average (1 min) at the start: {load_start:.2f}")
    compile_info = {} if args.skip_compile else compile_times(fresh_cache=not args.quick)

    data_all = build_quadrotor_data(config([f"runs={big}", f"duration={(steps + 1) * 0.01}"]))
    u_all = filter_inputs(data_all)
    single = build_quadrotor_data(config(["runs=1", f"duration={(steps + 1) * 0.01}"]))
    u1 = filter_inputs(single)
    alpha = 0.5

    def filterpy_us(vectorize: bool, repeats: int = 2) -> float:
        adapter = PerRunAdapter
        return min(
            time_steps(adapter(single.model, FilterpyUKF, alpha=alpha, vectorize_points=vectorize), single, u1, steps)
            for _ in range(repeats)
        )

    sr_single = min(time_steps(SRUKF(single.model, alpha), single, u1, steps) for _ in range(3))
    fp_plain_compiled, fp_vec_compiled = filterpy_us(False), filterpy_us(True)
    # The baseline as it was always measured: filterpy calling the model written in numpy (the
    # numpy backend also switches the model's f/h back to their numpy references).
    os.environ[square_root.KERNELS_ENV] = "numpy"
    fp_plain, fp_vec = filterpy_us(False), filterpy_us(True)
    sr_single_numpy = min(time_steps(SRUKF(single.model, alpha), single, u1, steps) for _ in range(2))
    est = SRUKF(data_all.model, alpha)
    batched_numpy = min(time_steps(est, data_all, u_all, steps) for _ in range(2)) / big
    os.environ.pop(square_root.KERNELS_ENV)
    print(f"single run, {single.model.name} (n={single.model.n}), alpha={alpha}, {steps} steps")
    print(f"  SR-UKF                                 {sr_single:9.1f} us/step")
    print(f"  SR-UKF on the numpy kernels and model  {sr_single_numpy:9.1f} us/step")
    print("  filterpy UKF calling the numpy model:")
    print(
        f"    per-point fx/hx                      {fp_plain:9.1f} us/step   SR-UKF ratio {sr_single / fp_plain:.2f}x"
    )
    print(f"    vectorised fx/hx                     {fp_vec:9.1f} us/step   SR-UKF ratio {sr_single / fp_vec:.2f}x")
    print("  filterpy UKF calling the compiled model:")
    print(
        f"    per-point fx/hx                      {fp_plain_compiled:9.1f} us/step   "
        f"SR-UKF ratio {sr_single / fp_plain_compiled:.2f}x"
    )
    print(
        f"    vectorised fx/hx                     {fp_vec_compiled:9.1f} us/step   "
        f"SR-UKF ratio {sr_single / fp_vec_compiled:.2f}x"
    )

    batched = {}
    for B in batches:
        sub = data_all if B == big else _subset(data_all, B)
        est = SRUKF(sub.model, alpha)
        batched[str(B)] = min(time_steps(est, sub, u_all[:B], steps) for _ in range(2)) / B
    print("batched SR-UKF, us per filter step per run:")
    for B, us in batched.items():
        print(
            f"  B={B:>5s}  {us:9.2f} us   speed-up over filterpy per-point loop {fp_plain / us:8.1f}x, "
            f"over vectorised filterpy loop {fp_vec / us:7.1f}x"
        )
    print(
        f"  B={big:>5d}  {batched_numpy:9.2f} us   on the numpy kernels "
        f"(speed-up over filterpy per-point loop {fp_plain / batched_numpy:.1f}x)"
    )
    speedup = fp_plain / batched[str(big)]
    print(
        f"  B={big:>5d}  speed-up over the filterpy per-point loop calling the compiled model "
        f"{fp_plain_compiled / batched[str(big)]:.1f}x"
    )
    kernels = kernel_ratios(big, **timing)
    threads = kernel_threads(big, **timing)
    print(f"square-root kernels at B={big}, us per call for the batch (compiled / numpy reference):")
    for name, k in kernels.items():
        print(f"  {name:13s} {k['numba_us']:9.1f} / {k['numpy_us']:9.1f}   ratio {k['compiled_over_numpy']:.3f}")
    for name, k in threads.items():
        print(
            f"  {name:13s} serial {k['serial_us']:9.1f} us, "
            f"parallel=True on {k['threads']} threads {k['parallel_us']:9.1f} us"
        )
    if compile_info:
        print(
            f"kernels' first calls in a fresh process: {compile_info['compile_s']:.2f} s compiling (empty cache), "
            f"{compile_info['cached_load_s']:.3f} s loading from the cache; "
            f"numba import {compile_info['numba_import_s']:.2f} s"
        )
    result = {
        "srukf_single_us": round(sr_single, 2),
        "filterpy_ukf_single_us": round(fp_plain, 2),
        "filterpy_ukf_vectorized_single_us": round(fp_vec, 2),
        "batched_us_per_step_run": {k: round(v, 3) for k, v in batched.items()},
        "speedup_vs_filterpy": round(speedup, 1),
        "peak_mem_mb": None,
        "srukf_over_filterpy_vectorized": round(sr_single / fp_vec, 3),
        "filterpy_ukf_compiled_model_single_us": round(fp_plain_compiled, 2),
        "filterpy_ukf_vectorized_compiled_model_single_us": round(fp_vec_compiled, 2),
        "srukf_over_filterpy_vectorized_compiled_model": round(sr_single / fp_vec_compiled, 3),
        "speedup_vs_filterpy_compiled_model": round(fp_plain_compiled / batched[str(big)], 1),
        "srukf_numpy_kernels_single_us": round(sr_single_numpy, 2),
        "batched_numpy_kernels_us_per_step_run": round(batched_numpy, 3),
        "kernels": kernels,
        "kernel_threads": threads,
        **compile_info,
        "peak_mem_mb_per_run": None,
    }
    if not args.skip_memory:
        runs, duration = (10, 0.5) if args.quick else (1000, 20.0)
        result["peak_mem_mb"] = round(peak_memory_mb(runs, duration), 1)
        result["peak_mem_mb_per_run"] = round(result["peak_mem_mb"] / runs, 3)
        print(
            f"peak RSS of a {runs}-run, {duration:g} s, 100 Hz batch (truth + SR-UKF + metrics): "
            f"{result['peak_mem_mb']} MB"
        )
    print(f"this process peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    result["load_average"] = {"start": round(load_start, 2), "end": round(os.getloadavg()[0], 2)}
    print(f"load average (1 min) at the end: {result['load_average']['end']:.2f}")
    if args.json:
        print(json.dumps(result))


def _subset(data, B: int):
    from dataclasses import replace

    return replace(
        data,
        model=data.model.select(slice(0, B)),
        truth=data.truth[:B],
        companion_truth=data.companion_truth[:B],
        inputs=data.inputs[:B],
        measurements=data.measurements[:B],
        x0=data.x0[:B],
        companion0=data.companion0[:B],
    )


if __name__ == "__main__":
    main()
