"""Conformance checks for estimator plugins (``docs/plugins.md``).

A plugin author runs, in their own test suite::

    from quadest.testing import check_estimator
    check_estimator(MyFilter, params={"alpha": 0.5}, bad_params=[{"alpha": -1.0}])

It raises ``AssertionError`` naming the first check that fails:

1. the class meets the contract (subclass, methods, declared capabilities, ``Params``);
2. on a linear-Gaussian model (2-D constant velocity, positions measured, correlated non-identity
   P0, Q, R, three runs with their own data) a Gaussian filter reproduces the Kalman filter
   (filterpy's ``KalmanFilter``) to ``rtol``;
3. shapes of mean, covariance and, when declared, innovation; symmetric covariances;
4. a batch gives each run what that run gives alone;
5. two fresh instances on the same data give identical numbers;
6. each entry of ``bad_params`` raises a ``ValueError`` with a message at construction.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from filterpy.kalman import KalmanFilter

from quadest.estimators.registry import contract_problems, make_estimator
from quadest.models.functional import LinearGaussianModel

__all__ = ["check_estimator", "linear_gaussian_problem"]


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T / n + 0.3 * np.eye(n))


def linear_gaussian_problem(runs: int = 3, steps: int = 60, seed: int = 0):
    """``(model, x0, P0, u, z)`` for a 2-D constant-velocity target with position measurements:
    n = 4, m = 2, correlated non-identity P0, Q and R, each run with its own truth and noise."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    A = np.eye(4)
    A[0, 2] = A[1, 3] = dt
    C = np.eye(2, 4)
    Q, R, P0 = _spd(rng, 4, 0.01), _spd(rng, 2, 0.2), _spd(rng, 4, 1.0)
    model = LinearGaussianModel(A, C, Q, R, dt=dt, batch_size=runs)
    LQ, LR, L0 = np.linalg.cholesky(Q), np.linalg.cholesky(R), np.linalg.cholesky(P0)
    x = np.empty((runs, steps + 1, 4))
    x[:, 0] = rng.standard_normal((runs, 4))
    for k in range(1, steps + 1):
        x[:, k] = x[:, k - 1] @ A.T + rng.standard_normal((runs, 4)) @ LQ.T
    z = x @ C.T + rng.standard_normal((runs, steps + 1, 2)) @ LR.T
    x0 = x[:, 0] + rng.standard_normal((runs, 4)) @ L0.T
    u = np.zeros((runs, steps + 1, 0))
    return model, x0, np.broadcast_to(P0, (runs, 4, 4)).copy(), u, z


def _run(est, x0, P0, u, z):
    est.initialize(x0.copy(), P0.copy())
    means, covs, innovations = [], [], []
    for k in range(1, z.shape[1]):
        est.predict(u[:, k - 1])
        est.update(z[:, k], u[:, k])
        means.append(np.array(est.mean, copy=True))
        covs.append(np.array(est.covariance, copy=True))
        if "innovation" in est.capabilities:
            innovations.append(tuple(np.array(a, copy=True) for a in est.innovation()))
    return np.array(means), np.array(covs), innovations


def _kalman(model, x0, P0, z):
    xs, Ps = [], []
    for i in range(x0.shape[0]):
        kf = KalmanFilter(dim_x=model.n, dim_z=model.m)
        kf.F, kf.H, kf.Q, kf.R = model.A, model.C, model.Q, model.R
        kf.x, kf.P = x0[i].copy(), P0[i].copy()
        run_x, run_P = [], []
        for k in range(1, z.shape[1]):
            kf.predict()
            kf.update(z[i, k])
            run_x.append(kf.x.copy())
            run_P.append(kf.P.copy())
        xs.append(run_x)
        Ps.append(run_P)
    return np.swapaxes(np.array(xs), 0, 1), np.swapaxes(np.array(Ps), 0, 1)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def check_estimator(
    cls: type,
    params: Mapping[str, Any] | None = None,
    bad_params: Sequence[Mapping[str, Any]] = (),
    gaussian: bool = True,
    rtol: float = 1e-9,
) -> None:
    """Run the conformance checks on estimator class ``cls`` (see the module docstring).

    Args:
        cls: a subclass of ``Estimator`` (batched) or ``SingleRunEstimator``.
        params: constructor parameters for the checks.
        bad_params: parameter sets that must be refused with a ``ValueError``.
        gaussian: whether the filter is a Gaussian filter that must equal the Kalman filter on a
            linear-Gaussian model (a particle filter would pass ``False``).
        rtol: relative tolerance of the Kalman-filter and batch checks.
    """
    name = getattr(cls, "__name__", repr(cls))
    problems = contract_problems(cls)
    assert not problems, f"{name}: contract: {'; '.join(problems)}"
    params = dict(params or {})
    model, x0, P0, u, z = linear_gaussian_problem()
    B, n, m = x0.shape[0], model.n, model.m

    est = make_estimator(cls, model, params)
    xs, Ps, innov = _run(est, x0, P0, u, z)
    K = z.shape[1] - 1
    assert xs.shape == (K, B, n), f"{name}: mean has shape {xs.shape[1:]}, expected {(B, n)}"
    assert Ps.shape == (K, B, n, n), f"{name}: covariance has shape {Ps.shape[1:]}, expected {(B, n, n)}"
    assert np.allclose(Ps, np.swapaxes(Ps, -1, -2), rtol=1e-10, atol=1e-12), f"{name}: covariance not symmetric"
    assert not np.any(est.failed), f"{name}: flagged runs on a benign linear problem: {est.failure_reasons}"
    if "innovation" in est.capabilities:
        nu, S = innov[-1]
        assert np.shape(nu) == (B, m) and np.shape(S) == (B, m, m), (
            f"{name}: innovation shapes {np.shape(nu)}, {np.shape(S)}, expected {(B, m)}, {(B, m, m)}"
        )
    if gaussian:
        xr, Pr = _kalman(model, x0, P0, z)
        assert _relative(xs, xr) <= rtol, f"{name}: mean differs from the Kalman filter by {_relative(xs, xr):.2e}"
        assert _relative(Ps, Pr) <= rtol, (
            f"{name}: covariance differs from the Kalman filter by {_relative(Ps, Pr):.2e}"
        )

    for i in range(B):
        alone = make_estimator(cls, model.select(i), params)
        xi, _, _ = _run(alone, x0[i : i + 1], P0[i : i + 1], u[i : i + 1], z[i : i + 1])
        assert _relative(xs[:, i], xi[:, 0]) <= rtol, f"{name}: run {i} in a batch differs from the run alone"

    again, _, _ = _run(make_estimator(cls, model, params), x0, P0, u, z)
    assert np.array_equal(again, xs), f"{name}: two fresh instances gave different numbers on the same data"

    for bad in bad_params:
        try:
            make_estimator(cls, model, {**params, **bad})
        except ValueError as exc:
            assert str(exc), f"{name}: bad parameters {dict(bad)} raised ValueError without a message"
        else:
            raise AssertionError(f"{name}: bad parameters {dict(bad)} were accepted")
