"""Benchmark the filterpy baselines per filter step and run: EKF against UKF, thesis quadrotor model.

Run: ``python benchmarks/bench_baselines.py`` (add ``--json`` for a machine-readable last line).

Measured in the same run, on the same data (the default job's ``runs`` = 50 runs, thesis filter
model n = 6, m = 6), as the job measures ``step_time_us`` (predict + update for the batch, per
run):

1. filterpy's UKF as quadest runs it (``estimator=ukf``: one filterpy UKF per run, the sigma
   points of every run through ``f`` and ``h`` in one model call each per step), with one
   vectorised model call per run (the 2n+1 points of that run; the previous adapter), and with
   filterpy's per-point ``fx``/``hx`` calls;
2. filterpy's EKF as quadest runs it (``estimator=ekf``: one filterpy EKF per run, ``f``, ``F``,
   ``h`` and ``H`` evaluated once per step for the whole batch);
3. filterpy's EKF with the four model calls made per run (the previous adapter; what a batch of
   one costs either way);
4. the model calls alone, at one point and for the whole batch;
5. the SR-UKF (``estimator=srukf``) on the compiled kernels and on the numpy references
   (``QUADEST_KERNELS=numba|numpy``, docs/benchmarks.md), for scale against the baselines.

The ratios printed are EKF / UKF from this run, against both the UKF as ``estimator=ukf`` runs it
now and the previous per-run adapter (the UKF step the target EKF ≤ 0.3× UKF was first set against).

``--quick`` runs every stage at toy sizes (4 runs, 3 steps, few repeats): what the test suite runs
so that a broken script fails it (tests/test_benchmarks_quick.py). Its numbers mean nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import time

from bench_srukf import config, filter_inputs, time_steps
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.filterpy_ekf import BatchedFilterpyEKF, FilterpyEKF
from quadest.estimators.filterpy_ukf import BatchedFilterpyUKF, FilterpyUKF
from quadest.estimators.srukf import SRUKF
from quadest.numerics.square_root import KERNELS_ENV
from quadest.simulation.registry import build_data

RUNS = 50


def call_time_us(fun, repeats: int = 300) -> float:
    """Mean wall time of ``fun()`` in µs (best of three blocks of ``repeats`` calls)."""
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        for _ in range(repeats):
            fun()
        best = min(best, (time.perf_counter() - start) / repeats * 1e6)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="end with one JSON line of the results")
    parser.add_argument("--steps", type=int, default=100, help="filter steps timed per measurement")
    parser.add_argument("--quick", action="store_true", help="every stage at toy sizes, numbers meaningless (tests)")
    args = parser.parse_args()
    steps, runs, call_repeats = (3, 4, 2) if args.quick else (args.steps, RUNS, 300)
    data = build_data(config([f"runs={runs}", f"duration={(steps + 1) * 0.01}"]))
    u = filter_inputs(data)
    model = data.model

    def per_run_us(make, repeats: int = 2) -> float:
        return min(time_steps(make(), data, u, steps) for _ in range(repeats)) / runs

    result = {
        "runs": runs,
        "steps": steps,
        "ukf_us": per_run_us(lambda: BatchedFilterpyUKF(model, alpha=0.5)),
        "ukf_per_run_calls_us": per_run_us(lambda: PerRunAdapter(model, FilterpyUKF, alpha=0.5)),
        "ukf_per_point_us": per_run_us(lambda: PerRunAdapter(model, FilterpyUKF, alpha=0.5, vectorize_points=False), 1),
        "ekf_us": per_run_us(lambda: BatchedFilterpyEKF(model), 3),
        "ekf_per_run_calls_us": per_run_us(lambda: PerRunAdapter(model, FilterpyEKF)),
        "srukf_us": per_run_us(lambda: SRUKF(model, alpha=0.5)),
    }
    os.environ[KERNELS_ENV] = "numpy"
    result["srukf_numpy_kernels_us"] = per_run_us(lambda: SRUKF(model, alpha=0.5))
    os.environ.pop(KERNELS_ENV)
    x, u0 = data.x0, u[:, 0]
    one, x1, u1 = model.select(0), x[:1], u0[:1]
    calls = {
        "f": (lambda: one.f(x1[:, None], u1), lambda: model.f(x[:, None], u0)),
        "F": (lambda: one.F(x1, u1), lambda: model.F(x, u0)),
        "h": (lambda: one.h(x1[:, None], u1), lambda: model.h(x[:, None], u0)),
        "f_numpy": (lambda: one.f_numpy(x1[:, None], u1), lambda: model.f_numpy(x[:, None], u0)),
        "h_numpy": (lambda: one.h_numpy(x1[:, None], u1), lambda: model.h_numpy(x[:, None], u0)),
        "H": (lambda: one.H(x1, u1), lambda: model.H(x, u0)),
    }
    result["model_call_us"] = {
        name: {"one_point": call_time_us(single, call_repeats), f"batch_{runs}": call_time_us(batch, call_repeats)}
        for name, (single, batch) in calls.items()
    }
    result["ekf_over_ukf"] = result["ekf_us"] / result["ukf_us"]
    result["ekf_over_ukf_per_run_calls"] = result["ekf_us"] / result["ukf_per_run_calls_us"]
    result["ekf_per_run_calls_over_ukf"] = result["ekf_per_run_calls_us"] / result["ukf_us"]

    print(f"{model.name} (n={model.n}, m={model.m}), {runs} runs, {steps} steps, us per filter step per run")
    print(f"  filterpy UKF, model evaluated per batch (estimator=ukf){result['ukf_us']:8.1f}")
    print(f"  filterpy UKF, one model call per run                   {result['ukf_per_run_calls_us']:8.1f}")
    print(f"  filterpy UKF, per-point fx/hx                          {result['ukf_per_point_us']:8.1f}")
    print(
        f"  filterpy EKF, model evaluated per batch (estimator=ekf){result['ekf_us']:8.1f}"
        f"   EKF/UKF {result['ekf_over_ukf']:.2f}x (against one UKF model call per run:"
        f" {result['ekf_over_ukf_per_run_calls']:.2f}x)"
    )
    print(
        f"  filterpy EKF, four model calls per run                 {result['ekf_per_run_calls_us']:8.1f}"
        f"   EKF/UKF {result['ekf_per_run_calls_over_ukf']:.2f}x"
    )
    print(f"  SR-UKF, compiled kernels (estimator=srukf)             {result['srukf_us']:8.1f}")
    print(f"  SR-UKF, numpy references (QUADEST_KERNELS=numpy)       {result['srukf_numpy_kernels_us']:8.1f}")
    print("model calls, us per call (one point / the whole batch; f and h compiled, *_numpy their references):")
    for name, times in result["model_call_us"].items():
        print(f"  {name:8s} {times['one_point']:7.1f} / {times[f'batch_{runs}']:7.1f}")
    if args.json:
        rounded = {k: round(v, 3) if isinstance(v, float) else v for k, v in result.items()}
        calls_us = result["model_call_us"]
        rounded["model_call_us"] = {name: {k: round(t, 1) for k, t in v.items()} for name, v in calls_us.items()}
        print(json.dumps(rounded))


if __name__ == "__main__":
    main()
