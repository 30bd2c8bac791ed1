"""Benchmark quadest's batched EKF, UKF and SR-UKF against dynamax's EKF and UKF (JAX).

Run: ``python benchmarks/bench_dynamax.py --dynamax-python PYTHON`` (add ``--json`` for a
machine-readable last line). dynamax needs JAX, which must never be a quadest dependency, so it
runs in a separate environment whose Python is given by ``--dynamax-python`` (or
``QUADEST_DYNAMAX_PYTHON``)::

    python -m venv /tmp/dynamax-env && /tmp/dynamax-env/bin/pip install dynamax jax
    python benchmarks/bench_dynamax.py --dynamax-python /tmp/dynamax-env/bin/python

(CPU jax; ``dynamax_filters.py`` is the script that environment runs.) Without it, quadest's
filters are timed alone and the script prints a note.

Same models, same data, same filter parameters on both sides, at B = 1, 100, 1000 runs:

- **UNGM** (``experiment=ungm_toolbox``: Q = R = 1, x0 = 0.1, P0 = 1; quadest's data), 100 steps;
- **attitude, 6 × 6**: a model of the thesis quadrotor's size (6 states, 6 measurements, as the
  thesis filter model) written in both numpy (here) and JAX (``dynamax_filters.py``): roll,
  pitch, yaw and body rates; Euler-angle kinematics, rates damped at 2 s⁻¹ and driven by a torque
  input, one Euler step of 10 ms; measured: gravity in the body frame (accelerometer) and the
  body rates (gyroscope). The thesis model itself (rotor inputs, companion integration, the MIMU
  error model) is not written in JAX. 200 steps, data simulated here from one seed.

quadest's filters: ``mekf`` (the batched EKF; on a vector state it is the EKF), the sigma-point
family's covariance-form UKF (``SigmaPointKalmanFilter`` with the unscented rule: what ``ukf``
computes, batched) and ``srukf``; UT parameters α = 0.5, β = 2, κ = 0 on both sides. Each keeps
the mean and covariance of every step (dynamax returns them as its scan's outputs); quadest's time
is predict + update per step and run, dynamax's the ``jit(vmap)`` call per step and run (its K + 1
steps, see ``dynamax_filters.py``), both in wall time and in CPU time (``process_time``, which
counts every thread: on a shared machine the steadier of the two), and dynamax's compile time is
reported apart. quadest's
first-step time (building the filter and loading its compiled kernels) is reported the same way.

**Correctness before timing**: at the largest B the two sides' posterior means and covariances
must agree at every step and run to within round-off, measured as the same comparison between
quadest's own UKF and SR-UKF (two float64 implementations of the same filter; ``ROUND_OFF_FACTOR``
below). A mismatch is an error, and no timing is printed.

``--quick`` runs every stage at toy sizes (B = 1 and 4, 5 steps, one repeat): what the test suite
runs so that a broken script fails it (tests/test_benchmarks_quick.py). Its numbers mean nothing.
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
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from quadest.app.schema import register_schemas
from quadest.app.settings import data_settings
from quadest.config.paths import config_dir
from quadest.estimators.base import Estimator
from quadest.estimators.error_state_ekf import ErrorStateEKF
from quadest.estimators.sigma_point import SigmaPointKalmanFilter
from quadest.estimators.srukf import SRUKF
from quadest.models.base import FilterModel
from quadest.models.functional import FunctionalModel
from quadest.models.validation import UNGMModel
from quadest.numerics.rules import UnscentedRule
from quadest.simulation.validation_data import build_ungm_data

BATCHES = (1, 100, 1000)
QUICK_BATCHES = (1, 4)
ALPHA, BETA, KAPPA = 0.5, 2.0, 0.0
AGREEMENT = 1e-6
ROUND_OFF_FACTOR = 10.0
"""The two sides' estimates must agree to ``max(AGREEMENT, ROUND_OFF_FACTOR × d)`` posterior
standard deviations (means) and relative (covariances), where ``d`` is the same difference between
quadest's own covariance-form UKF and SR-UKF on that model: two float64 implementations of one
recursion differ by round-off, amplified along the run, and dynamax cannot be asked to be closer to
quadest than quadest's two forms are to each other. On the attitude model ``d`` is 10⁻¹³ (the limit
is then 10⁻⁶); on UNGM, whose UKF amplifies round-off over 100 steps (P collapses and regrows
near x = 0), ``d`` reaches 10⁻³ at B = 1000. A different filter is caught: dynamax's UKF with
β = 0 instead of 2, in ``--quick`` (4 runs, 5 steps), differs by 1.6 standard deviations on UNGM
and by 1.5·10⁻⁶ on the nearly linear attitude model (its limit 10⁻⁶)."""

G, RATE_DAMPING, DT = 9.81, 2.0, 0.01  # as dynamax_filters.py


def attitude_f(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The attitude model's ``f`` on (B, K, 6) points, inputs (B, 3) (module docstring)."""
    phi, theta = x[..., 0], x[..., 1]
    p, q, r = x[..., 3], x[..., 4], x[..., 5]
    s, c, t = np.sin(phi), np.cos(phi), np.tan(theta)
    out = np.empty_like(x)
    out[..., 0] = x[..., 0] + DT * (p + s * t * q + c * t * r)
    out[..., 1] = x[..., 1] + DT * (c * q - s * r)
    out[..., 2] = x[..., 2] + DT * (s * q + c * r) / np.cos(theta)
    out[..., 3:6] = x[..., 3:6] + DT * (-RATE_DAMPING * x[..., 3:6] + u[:, None, :])
    return out


def attitude_h(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The attitude model's ``h``: gravity in the body frame and the body rates."""
    phi, theta = x[..., 0], x[..., 1]
    out = np.empty_like(x)
    out[..., 0] = -G * np.sin(theta)
    out[..., 1] = G * np.sin(phi) * np.cos(theta)
    out[..., 2] = G * np.cos(phi) * np.cos(theta)
    out[..., 3:6] = x[..., 3:6]
    return out


def attitude_F(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """∂f/∂x (B, 6, 6) of :func:`attitude_f` at ``x`` (B, 6), analytic (dynamax differentiates its
    JAX ``f`` exactly, by ``jacfwd``)."""
    phi, theta = x[:, 0], x[:, 1]
    q, r = x[:, 4], x[:, 5]
    s, c, t, ct = np.sin(phi), np.cos(phi), np.tan(theta), np.cos(theta)
    J = np.zeros((x.shape[0], 6, 6))
    J[:, 0, 0], J[:, 0, 1] = c * t * q - s * t * r, (s * q + c * r) / ct**2
    J[:, 1, 0] = -s * q - c * r
    J[:, 2, 0], J[:, 2, 1] = (c * q - s * r) / ct, (s * q + c * r) * np.sin(theta) / ct**2
    J[:, 0, 3], J[:, 0, 4], J[:, 0, 5] = 1.0, s * t, c * t
    J[:, 1, 4], J[:, 1, 5] = c, -s
    J[:, 2, 4], J[:, 2, 5] = s / ct, c / ct
    J[:, 3:6, 3:6] = -RATE_DAMPING * np.eye(3)
    return np.eye(6) + DT * J


def attitude_H(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """∂h/∂x (B, 6, 6) of :func:`attitude_h`, analytic."""
    sp, cp, st, ct = np.sin(x[:, 0]), np.cos(x[:, 0]), np.sin(x[:, 1]), np.cos(x[:, 1])
    J = np.zeros((x.shape[0], 6, 6))
    J[:, 0, 1] = -G * ct
    J[:, 1, 0], J[:, 1, 1] = G * cp * ct, -G * sp * st
    J[:, 2, 0], J[:, 2, 1] = -G * sp * ct, -G * cp * st
    J[:, 3:6, 3:6] = np.eye(3)
    return J


ATTITUDE_Q = np.diag([1e-6, 1e-6, 1e-6, 1e-4, 1e-4, 1e-4])
ATTITUDE_R = np.diag([0.05**2] * 3 + [0.01**2] * 3)
ATTITUDE_P0 = np.diag([0.05**2] * 3 + [0.1**2] * 3)


def attitude_model(B: int) -> FunctionalModel:
    return FunctionalModel(
        attitude_f, attitude_h, ATTITUDE_Q, ATTITUDE_R, nu=3, dt=DT, jacobians=(attitude_F, attitude_H), batch_size=B,
        name="attitude",
    )  # fmt: skip


def attitude_problem(runs: int, steps: int, seed: int = 20261127) -> dict[str, np.ndarray]:
    """Simulated runs of the attitude model: truth from x0 ~ N(0, P0), torques 0.5 sin(ωt + φ)
    with random phases, additive Gaussian noise Q and R; the filters start at 0 with P0."""
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    t = np.arange(steps + 1) * DT
    phases = rng.uniform(0.0, 2 * np.pi, (runs, 1, 3))
    u = 0.5 * np.sin(2.0 * t[None, :, None] + phases)
    x = rng.standard_normal((runs, 6)) @ np.linalg.cholesky(ATTITUDE_P0).T
    z = np.zeros((runs, steps + 1, 6))
    for k in range(1, steps + 1):
        x = attitude_f(x[:, None], u[:, k - 1])[:, 0] + rng.standard_normal((runs, 6)) @ np.sqrt(ATTITUDE_Q)
        z[:, k] = attitude_h(x[:, None], u[:, k])[:, 0] + rng.standard_normal((runs, 6)) @ np.sqrt(ATTITUDE_R)
    return {"x0": np.zeros((runs, 6)), "P0": ATTITUDE_P0, "Q": ATTITUDE_Q, "R": ATTITUDE_R, "u": u, "z": z}


def ungm_problem(runs: int, steps: int) -> dict[str, np.ndarray]:
    """quadest's ``experiment=ungm_toolbox`` data, the first ``steps`` steps."""
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=config_dir(), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["experiment=ungm_toolbox", f"runs={runs}"])
    data = build_ungm_data(data_settings(cfg))
    model = data.model
    return {
        "x0": data.x0,
        "P0": data.P0,
        "Q": model.Q,
        "R": model.R,
        "u": data.inputs[:, : steps + 1],
        "z": data.measurements[:, : steps + 1],
    }


MODELS: dict[str, Callable[[int], FilterModel]] = {
    "ungm": lambda B: UNGMModel(1.0, 1.0, 1.0, B),
    "attitude": attitude_model,
}
FILTERS: dict[str, Callable[[FilterModel], Estimator]] = {
    "mekf": ErrorStateEKF,
    "ukf": lambda model: SigmaPointKalmanFilter(model, UnscentedRule(ALPHA, BETA, KAPPA)),
    "srukf": lambda model: SRUKF(model, ALPHA, BETA, KAPPA),
}
DYNAMAX_PEER = {"mekf": "ekf", "ukf": "ukf", "srukf": "ukf"}


def run_filter(name: str, kind: str, problem: dict, B: int) -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """quadest's filter on the first B runs: means (B, K, n) and covariances (B, K, n, n) after
    each update k = 1 … K, the first step's time (building, kernels, initialise, one step), and
    the wall and CPU time (``process_time``) of the remaining steps, in s."""
    u, z = problem["u"][:B], problem["z"][:B]
    steps, n = z.shape[1] - 1, problem["x0"].shape[1]
    means, covs = np.empty((B, steps, n)), np.empty((B, steps, n, n))
    start = time.perf_counter()
    est = FILTERS[kind](MODELS[name](B))
    est.initialize(problem["x0"][:B].copy(), np.broadcast_to(problem["P0"], (B, n, n)).copy())
    for k in range(1, steps + 1):
        if k == 2:
            first = time.perf_counter() - start
            start, cpu = time.perf_counter(), time.process_time()
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        means[:, k - 1] = est.mean
        covs[:, k - 1] = est.covariance
    return means, covs, first, time.perf_counter() - start, time.process_time() - cpu


def differences(means_a, covs_a, means_b, covs_b) -> dict[str, float]:
    """Largest difference of the means in posterior standard deviations (of ``covs_a``) and of
    the covariances relative to the diagonal scale, over every run and step."""
    sd = np.sqrt(np.diagonal(covs_a, axis1=-2, axis2=-1))
    scale = np.sqrt(sd[..., :, None] * sd[..., None, :])
    return {
        "mean_sd": float(np.max(np.abs(means_a - means_b) / sd)),
        "covariance_rel": float(np.max(np.abs(covs_a - covs_b) / scale**2)),
    }


def run_dynamax(python: str, problems: dict[str, dict], batches, repeats: int) -> tuple[dict, dict]:
    """``dynamax_filters.py`` under ``python`` on the same problems: its JSON and its estimates."""
    with tempfile.TemporaryDirectory() as tmp:
        path, out = Path(tmp) / "problems.npz", Path(tmp) / "estimates.npz"
        arrays = {f"{name}_{key}": value for name, p in problems.items() for key, value in p.items()}
        np.savez(path, models=np.array(list(problems)), batches=np.array(batches), repeats=repeats,
                 alpha=ALPHA, beta=BETA, kappa=KAPPA, **arrays)  # fmt: skip
        script = Path(__file__).with_name("dynamax_filters.py")
        done = subprocess.run([python, str(script), str(path), str(out)], capture_output=True, text=True)
        if done.returncode:
            raise RuntimeError(f"dynamax_filters.py failed under {python}:\n{done.stderr[-2000:]}")
        with np.load(out) as estimates:
            return json.loads(done.stdout.strip().splitlines()[-1]), dict(estimates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="end with one JSON line of the results")
    parser.add_argument(
        "--dynamax-python",
        default=os.environ.get("QUADEST_DYNAMAX_PYTHON"),
        help="Python of a separate environment with dynamax and jax (default: $QUADEST_DYNAMAX_PYTHON)",
    )
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats, best kept")
    parser.add_argument("--quick", action="store_true", help="every stage at toy sizes, numbers meaningless (tests)")
    args = parser.parse_args()
    batches = QUICK_BATCHES if args.quick else BATCHES
    repeats = 1 if args.quick else args.repeats
    steps = {"ungm": 5, "attitude": 5} if args.quick else {"ungm": 100, "attitude": 200}
    load = [os.getloadavg()]
    big = max(batches)
    problems = {"ungm": ungm_problem(big, steps["ungm"]), "attitude": attitude_problem(big, steps["attitude"])}

    ours: dict[str, dict] = {}
    estimates: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, problem in problems.items():
        for kind in FILTERS:
            for B in batches:
                best, best_cpu, first = float("inf"), float("inf"), 0.0
                for _ in range(repeats):
                    means, covs, first, elapsed, cpu = run_filter(name, kind, problem, B)
                    best, best_cpu = min(best, elapsed), min(best_cpu, cpu)
                ours[f"{name}/{kind}/{B}"] = {
                    "first_step_s": first,
                    "us_per_step_run": best / (B * (steps[name] - 1)) * 1e6,
                    "cpu_us_per_step_run": best_cpu / (B * (steps[name] - 1)) * 1e6,
                }
                if B == big:
                    estimates[f"{name}/{kind}"] = (means, covs)
    load.append(os.getloadavg())

    agreement: dict[str, dict[str, float]] = {}
    for name in problems:
        agreement[f"{name}: ukf vs srukf (quadest, round-off scale)"] = differences(
            *estimates[f"{name}/ukf"], *estimates[f"{name}/srukf"]
        )
    peer = None
    if args.dynamax_python:
        peer, peer_estimates = run_dynamax(args.dynamax_python, problems, batches, repeats)
        load.append(os.getloadavg())
        for name in problems:
            for kind, dyn in DYNAMAX_PEER.items():
                their = (
                    peer_estimates[f"{name}_{dyn}_means"][:, 1:],
                    peer_estimates[f"{name}_{dyn}_covariances"][:, 1:],
                )
                agreement[f"{name}: {kind} vs dynamax {dyn}"] = differences(*estimates[f"{name}/{kind}"], *their)

    print(f"1-minute load average at the start: {load[0][0]:.2f} ({os.cpu_count()} cores)")
    limits = {
        name: max(
            AGREEMENT, ROUND_OFF_FACTOR * max(agreement[f"{name}: ukf vs srukf (quadest, round-off scale)"].values())
        )
        for name in problems
    }
    print(f"agreement at B = {big}, largest over runs and steps:")
    for label, diff in agreement.items():
        limit = limits[label.split(":")[0]]
        print(
            f"  {label:42s} means {diff['mean_sd']:9.2e} sd, covariances {diff['covariance_rel']:9.2e}"
            f"   (limit {limit:.1e})"
        )
    failed = [label for label, d in agreement.items() if max(d.values()) > limits[label.split(":")[0]]]
    if failed:
        raise SystemExit(f"the filters disagree beyond round-off: {', '.join(failed)}; no timing printed")

    print(
        "µs per step and run, wall / CPU (quadest: predict + update; dynamax: the jit(vmap) call); "
        "ratio quadest ÷ dynamax, wall / CPU:"
    )
    for name in problems:
        for kind in FILTERS:
            for B in batches:
                mine = ours[f"{name}/{kind}/{B}"]
                line = (
                    f"  {name:8s} {kind:5s} B={B:>5d}  quadest {mine['us_per_step_run']:8.2f} / "
                    f"{mine['cpu_us_per_step_run']:8.2f} (first step {mine['first_step_s']:.3f} s)"
                )
                if peer is not None:
                    theirs = peer["timings"][f"{name}/{DYNAMAX_PEER[kind]}/{B}"]
                    wall = mine["us_per_step_run"] / theirs["us_per_step_run"]
                    cpu = mine["cpu_us_per_step_run"] / theirs["cpu_us_per_step_run"]
                    line += (
                        f"   dynamax {DYNAMAX_PEER[kind]} {theirs['us_per_step_run']:8.2f} / "
                        f"{theirs['cpu_us_per_step_run']:8.2f} (compile {theirs['compile_s']:.2f} s)"
                        f"   ratio {wall:6.2f} / {cpu:6.2f}"
                    )
                print(line)
    if peer is None:
        print("dynamax: skipped (JAX is not a quadest dependency; give --dynamax-python, see this script's docstring)")
    else:
        print(
            f"dynamax {peer['dynamax_version']}, jax {peer['jax_version']}, numpy {peer['numpy_version']}, "
            f"{peer['devices']}"
        )
    load.append(os.getloadavg())
    print(f"1-minute load average at the end: {load[-1][0]:.2f}")
    if args.json:
        print(json.dumps({"quadest": ours, "dynamax": peer, "agreement": agreement, "load_average": load}))


if __name__ == "__main__":
    main()
