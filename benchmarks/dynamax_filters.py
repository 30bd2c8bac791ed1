"""dynamax's EKF and UKF on quadest's data, timed: the dynamax column of ``bench_dynamax.py``.
Runs in a *separate* environment (JAX must never be a quadest dependency); imports only numpy,
jax and dynamax, never quadest.

Usage (``bench_dynamax.py --dynamax-python PYTHON`` does this for you)::

    python dynamax_filters.py PROBLEMS.npz OUT.npz

``PROBLEMS.npz`` (written by ``bench_dynamax.py``) holds, for each model ``<name>`` of its
``models`` list: ``<name>_x0`` (B, n) and ``<name>_P0`` (n, n), the start of every run;
``<name>_Q``, ``<name>_R``; ``<name>_u`` (B, K + 1, nu), the inputs u_0 … u_K; ``<name>_z``
(B, K + 1, m), the measurements z_1 … z_K after a row for step 0 that is never used; and
``batches``, ``repeats``, ``alpha``, ``beta``, ``kappa``. The models' ``f`` and ``h`` are written
below in JAX, the same equations as ``bench_dynamax.py`` writes in numpy.

quadest's filters start at (x0, P0), then each step k = 1 … K predicts with u_{k−1} and updates
with z_k (using u_k). dynamax conditions first, then predicts, and its prediction from t to t + 1
reads ``inputs[t + 1]``; so dynamax's step 0 conditions on a flat dummy observation (R = 10¹⁶ I:
its gain moves the mean and covariance by less than their round-off), its input at step t is
``[u_{t−1}, u_t]``, ``f`` reads the first half and ``h`` the second, and dynamax's filtered means
and covariances at t = 1 … K are quadest's posteriors at k = 1 … K. The dummy step is counted in
dynamax's time per step (K + 1 steps).

Each (model, filter, B) is ``jax.jit(jax.vmap(filter))`` over the first B runs, float64
(``jax_enable_x64``), returning the filtered means and covariances of every step (what a
comparison of estimators reads: errors and NEES). dynamax's gain solve runs without its 10⁻⁹
diagonal boost (``_exact_solve``), so that both sides compute the same filter. The compile time
(``lower`` + ``compile``) is
reported apart from the run time (best of ``repeats`` calls, ``block_until_ready``), in wall time
and in CPU time (``process_time``: every thread of XLA's pool counted). Prints one
JSON line; ``OUT.npz`` holds the means and covariances at the largest B for the correctness check.
"""

from __future__ import annotations

import json
import sys
import time
from importlib.metadata import version

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402  (after the float64 switch)
import numpy as np  # noqa: E402
from dynamax.nonlinear_gaussian_ssm import (  # noqa: E402
    ParamsNLGSSM,
    UKFHyperParams,
    extended_kalman_filter,
    inference_ekf,
    inference_ukf,
    unscented_kalman_filter,
)
from dynamax.utils.utils import psd_solve  # noqa: E402


def _exact_solve(A, b):
    """dynamax's ``psd_solve`` without its diagonal boost (it adds 10⁻⁹ I to the innovation
    covariance before the gain, a regularisation that is not part of the EKF or the UKF and that
    moves the attitude model's estimates by ~10⁻⁵ of a standard deviation, its gyro R being 10⁻⁴)."""
    return psd_solve(A, b, diagonal_boost=0.0)


inference_ekf.psd_solve = inference_ukf.psd_solve = _exact_solve

DUMMY_VARIANCE = 1e16
G = 9.81
RATE_DAMPING = 2.0  # 1/s
DT = 0.01


def ungm(x, u):
    """UNGM (Kitagawa 1996; quadest's ``model=ungm``): f and h at one point."""
    f = 0.5 * x + 25.0 * x / (1.0 + x**2) + 8.0 * jnp.cos(1.2 * u[0])
    return f, x**2 / 20.0


def attitude_f(x, u):
    """Rigid-body attitude, 6 states (roll, pitch, yaw, body rates p, q, r): Euler kinematics and
    damped rates driven by the torque input, one explicit Euler step of DT."""
    phi, theta = x[0], x[1]
    p, q, r = x[3], x[4], x[5]
    s, c, t = jnp.sin(phi), jnp.cos(phi), jnp.tan(theta)
    angle_rates = jnp.stack([p + s * t * q + c * t * r, c * q - s * r, (s * q + c * r) / jnp.cos(theta)])
    rates_dot = -RATE_DAMPING * x[3:6] + u
    return jnp.concatenate([x[0:3] + DT * angle_rates, x[3:6] + DT * rates_dot])


def attitude_h(x):
    """Gravity in the body frame (accelerometer, 3) and the body rates (gyroscope, 3)."""
    phi, theta = x[0], x[1]
    g = G * jnp.stack([-jnp.sin(theta), jnp.sin(phi) * jnp.cos(theta), jnp.cos(phi) * jnp.cos(theta)])
    return jnp.concatenate([g, x[3:6]])


def model_functions(name: str, nu: int):
    """dynamax's ``f(x, inputs[t+1])`` and ``h(x, inputs[t])`` from inputs ``[u_{t−1}, u_t]``."""
    if name == "ungm":
        return (lambda x, v: ungm(x, v[:nu])[0]), (lambda x, v: ungm(x, v[nu:])[1])
    if name == "attitude":
        return (lambda x, v: attitude_f(x, v[:nu])), (lambda x, v: attitude_h(x))
    raise ValueError(f"unknown model {name!r}: allowed ungm, attitude")


def sequences(problems, name: str):
    """dynamax's inputs ``[u_{t−1}, u_t]`` and the measurements, for every run."""
    u = problems[f"{name}_u"]
    previous = np.concatenate([np.zeros_like(u[:, :1]), u[:, :-1]], axis=1)
    z = problems[f"{name}_z"].copy()
    z[:, 0] = 0.0
    return np.concatenate([previous, u], axis=-1), z


def filter_function(name: str, kind: str, problems):
    """One run's filter: (x0, inputs, measurements) → (means, covariances) at t = 0 … K."""
    Q, R = jnp.asarray(problems[f"{name}_Q"]), jnp.asarray(problems[f"{name}_R"])
    P0 = jnp.asarray(problems[f"{name}_P0"])
    steps, m = problems[f"{name}_z"].shape[1], R.shape[0]
    R_t = jnp.concatenate([DUMMY_VARIANCE * jnp.eye(m)[None], jnp.broadcast_to(R, (steps - 1, m, m))])
    f, h = model_functions(name, problems[f"{name}_u"].shape[-1])
    hyper = UKFHyperParams(alpha=float(problems["alpha"]), beta=float(problems["beta"]), kappa=float(problems["kappa"]))
    fields = ["filtered_means", "filtered_covariances"]

    def run(x0, inputs, z):
        params = ParamsNLGSSM(x0, P0, f, Q, h, R_t)
        if kind == "ekf":
            post = extended_kalman_filter(params, z, inputs=inputs, output_fields=fields)
        else:
            post = unscented_kalman_filter(params, z, hyper, inputs=inputs, output_fields=fields)
        return post.filtered_means, post.filtered_covariances

    return run


def main() -> None:
    problems = dict(np.load(sys.argv[1]))
    out_path = sys.argv[2]
    models = [str(name) for name in problems["models"]]
    batches, repeats = [int(b) for b in problems["batches"]], int(problems["repeats"])
    timings: dict[str, dict] = {}
    estimates: dict[str, np.ndarray] = {}
    for name in models:
        inputs_all, z_all = sequences(problems, name)
        x0_all = problems[f"{name}_x0"]
        steps = z_all.shape[1]
        for kind in ("ekf", "ukf"):
            batched = jax.jit(jax.vmap(filter_function(name, kind, problems)))
            for B in batches:
                args = tuple(jnp.asarray(a[:B]) for a in (x0_all, inputs_all, z_all))
                start = time.perf_counter()
                compiled = batched.lower(*args).compile()
                compile_s = time.perf_counter() - start
                best, best_cpu = float("inf"), float("inf")
                for _ in range(repeats):
                    start, cpu = time.perf_counter(), time.process_time()
                    means, covs = jax.block_until_ready(compiled(*args))
                    best = min(best, time.perf_counter() - start)
                    best_cpu = min(best_cpu, time.process_time() - cpu)
                timings[f"{name}/{kind}/{B}"] = {
                    "compile_s": compile_s,
                    "run_s": best,
                    "us_per_step_run": best / (B * steps) * 1e6,
                    "cpu_us_per_step_run": best_cpu / (B * steps) * 1e6,
                }
                if B == max(batches):
                    estimates[f"{name}_{kind}_means"] = np.asarray(means)
                    estimates[f"{name}_{kind}_covariances"] = np.asarray(covs)
    np.savez(out_path, **estimates)
    result = {
        "timings": timings,
        "dynamax_version": version("dynamax"),
        "jax_version": jax.__version__,
        "numpy_version": np.__version__,
        "devices": [str(d) for d in jax.devices()],
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
