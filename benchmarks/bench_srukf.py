"""Benchmark the batched SR-UKF against filterpy's UKF on the thesis quadrotor filter model.

Run: ``python benchmarks/bench_srukf.py`` (add ``--json`` for a machine-readable last line).

Everything is measured in the same run, on the same data:

1. single-run step time (predict + update) of the SR-UKF and of filterpy 2.0's UKF, the latter
   both as filterpy is normally used (``fx``/``hx`` called once per sigma point) and with the
   sigma points evaluated in one vectorised call (what quadest's UKF baseline does);
2. batched throughput of the SR-UKF in µs per filter step per run at B = 1, 10, 100, 1000, and
   the speed-up at B = 1000 over filterpy's UKF looped over runs (per-point use);
3. peak resident memory of a full 1000-run, 20 s, 100 Hz batch (truth, sensors and the
   SR-UKF with the runner's metrics), measured in a separate process.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from quadest.config.paths import config_dir
from quadest.config.schema import register_schemas
from quadest.estimators.base import PerRunAdapter
from quadest.estimators.filterpy_ukf import FilterpyUKF
from quadest.estimators.srukf import SRUKF
from quadest.models.quadrotor_data import build_quadrotor_data

BATCHES = (1, 10, 100, 1000)


def config(overrides: list[str]):
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        return compose(config_name="config", overrides=overrides)


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


def peak_memory_mb(runs: int) -> float:
    """Peak RSS of a child process that runs the full batch through the runner."""
    script = f"""
import resource
from hydra import compose, initialize_config_dir
from quadest.config.paths import config_dir
from quadest.config.schema import register_schemas
from quadest.estimators.srukf import SRUKF
from quadest.models.quadrotor_data import build_quadrotor_data
from quadest.runner import run_estimator
register_schemas()
with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
    cfg = compose(config_name="config", overrides=["runs={runs}"])
data = build_quadrotor_data(cfg)
run_estimator("srukf", SRUKF(data.model, 0.5), data, 50.0, saved_runs=3)
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0  # ru_maxrss is in KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="end with one JSON line of the results")
    parser.add_argument("--steps", type=int, default=200, help="filter steps timed per measurement")
    parser.add_argument("--skip-memory", action="store_true", help="skip the 1000-run memory measurement")
    args = parser.parse_args()
    steps = args.steps

    data_all = build_quadrotor_data(config([f"runs={max(BATCHES)}", f"duration={(steps + 1) * 0.01}"]))
    u_all = filter_inputs(data_all)
    single = build_quadrotor_data(config(["runs=1", f"duration={(steps + 1) * 0.01}"]))
    u1 = filter_inputs(single)
    alpha = 0.5

    sr_single = min(time_steps(SRUKF(single.model, alpha), single, u1, steps) for _ in range(3))
    fp_plain = min(
        time_steps(PerRunAdapter(single.model, FilterpyUKF, alpha=alpha, vectorize_points=False), single, u1, steps)
        for _ in range(2)
    )
    fp_vec = min(time_steps(PerRunAdapter(single.model, FilterpyUKF, alpha=alpha), single, u1, steps) for _ in range(2))
    print(f"single run, {single.model.name} (n={single.model.n}), alpha={alpha}, {steps} steps")
    print(f"  SR-UKF                                 {sr_single:9.1f} us/step")
    print(
        f"  filterpy UKF, per-point fx/hx          {fp_plain:9.1f} us/step   SR-UKF ratio {sr_single / fp_plain:.2f}x"
    )
    print(f"  filterpy UKF, vectorised fx/hx         {fp_vec:9.1f} us/step   SR-UKF ratio {sr_single / fp_vec:.2f}x")

    batched = {}
    for B in BATCHES:
        sub = data_all if B == max(BATCHES) else _subset(data_all, B)
        est = SRUKF(sub.model, alpha)
        batched[str(B)] = min(time_steps(est, sub, u_all[:B], steps) for _ in range(2)) / B
    print("batched SR-UKF, us per filter step per run:")
    for B, us in batched.items():
        print(
            f"  B={B:>5s}  {us:9.2f} us   speed-up over filterpy per-point loop {fp_plain / us:8.1f}x, "
            f"over vectorised filterpy loop {fp_vec / us:7.1f}x"
        )
    speedup = fp_plain / batched[str(max(BATCHES))]
    result = {
        "srukf_single_us": round(sr_single, 2),
        "filterpy_ukf_single_us": round(fp_plain, 2),
        "filterpy_ukf_vectorized_single_us": round(fp_vec, 2),
        "batched_us_per_step_run": {k: round(v, 3) for k, v in batched.items()},
        "speedup_vs_filterpy": round(speedup, 1),
        "peak_mem_mb": None,
    }
    if not args.skip_memory:
        result["peak_mem_mb"] = round(peak_memory_mb(1000), 1)
        print(f"peak RSS of a 1000-run, 20 s, 100 Hz batch (truth + SR-UKF + metrics): {result['peak_mem_mb']} MB")
    print(f"this process peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
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
