"""Shared builders for the tests: random smooth models, SPD matrices, quadrotor configs."""

from __future__ import annotations

import numpy as np

from quadest import conformance
from quadest.config.settings import DataSettings
from quadest.estimators.base import Estimator
from quadest.models.base import FilterModel
from quadest.models.functional import FunctionalModel


def random_spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    """A correlated, non-identity SPD matrix."""
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T / n + 0.3 * np.eye(n))


def smooth_model(seed: int, n: int = 4, m: int = 2, batch_size: int = 1) -> FunctionalModel:
    """A random smooth nonlinear model with correlated non-identity Q and R, m < n."""
    rng = np.random.default_rng(seed)
    A = 0.5 * rng.standard_normal((n, n))
    c = rng.uniform(0.5, 1.5, n)
    C = rng.standard_normal((m, n))
    dt = 0.1

    def f(x, u):
        return x + dt * (np.tanh(x) @ A.T + 0.3 * np.sin(c * x) + u[:, None, :n])

    def h(x, u):
        return np.tanh(x) @ C.T + 0.1 * x[..., :m] ** 2

    return FunctionalModel(f, h, random_spd(rng, n, 0.01), random_spd(rng, m, 0.1), nu=n, dt=dt, batch_size=batch_size)


def run_filter(est: Estimator, model: FilterModel, x0, P0, inputs, measurements, failures: dict | None = None):
    """Means (K, B, n) and covariances (K, B, n, n) after each update. If ``failures`` is given,
    it receives run → first step (1-based) at which the estimator flagged the run."""
    est.initialize(x0, P0)
    means, covs = [], []
    for k in range(1, inputs.shape[1]):
        est.predict(inputs[:, k - 1])
        est.update(measurements[:, k], inputs[:, k])
        means.append(est.mean.copy())
        covs.append(est.covariance.copy())
        if failures is not None:
            for i in np.flatnonzero(est.failed):
                failures.setdefault(int(i), k)
    return np.array(means), np.array(covs)


def simulate(model: FilterModel, x0: np.ndarray, steps: int, seed: int):
    """Truth, inputs and measurements of a FunctionalModel with its own Q and R."""
    rng = np.random.default_rng(seed)
    B, n = x0.shape
    LQ, LR = np.linalg.cholesky(model.Q), np.linalg.cholesky(model.R)
    u = 0.1 * rng.standard_normal((B, steps + 1, max(model.nu, 0)))
    x = np.empty((B, steps + 1, n))
    x[:, 0] = x0
    for k in range(1, steps + 1):
        x[:, k] = model.f(x[:, k - 1][:, None], u[:, k - 1])[:, 0] + rng.standard_normal((B, n)) @ LQ.T
    z = (
        model.h(x, u[:, 0])
        if model.nu == 0
        else np.stack([model.h(x[:, k][:, None], u[:, k])[:, 0] for k in range(steps + 1)], axis=1)
    )
    z = z + rng.standard_normal(z.shape) @ LR.T
    return x, u, z


def compose_config(overrides: list[str] | None = None):
    """The composed root config, as the CLI would see it, unchecked: tests hand it refused values."""
    return conformance.compose_config(overrides, checked=False)


def compose_settings(overrides: list[str] | None = None) -> DataSettings:
    """The typed data settings of the composed root config, unchecked: what a data builder takes."""
    return conformance.compose_settings(overrides, checked=False)
