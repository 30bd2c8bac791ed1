"""``model=upf_benchmark``: the scalar benchmark of van der Merwe, Doucet, de Freitas & Wan (2000),
"The unscented particle filter" (NIPS 13; tech. report CUED/F-INFENG/TR 380, §5.1):

- ``x_t = 1 + sin(0.04 π t) + 0.5 x_{t−1} + v_t`` with ``v_t ~ Gamma(shape 3, rate 2)``
  (mean 3/2, variance 3/4): non-Gaussian, skewed, zero for negative increments;
- ``y_t = 0.2 x_t² + n_t`` for ``t ≤ 30`` and ``y_t = 0.5 x_t − 2 + n_t`` for ``t > 30``,
  ``n_t ~ N(0, R)``, ``R = 1e-5``;
- ``x_1 = 1`` known exactly; the paper runs t = 1..60.

Sample ``k = 0..K`` is time ``t = k + 1`` and the input is that time index, ``u_k = t_k``, so
``f(x, u_{k−1})`` uses ``t = u + 1`` and ``h(x, u_k)`` uses ``t = u``. ``f`` is the transition
*without* the noise mean, as the paper's EKF and UKF predict; ``Q`` is the Gamma variance the
Gaussian filters assume (configurable). The particle filters use the true Gamma density through
:meth:`UPFBenchmarkModel.sample_process_noise` and :meth:`UPFBenchmarkModel.process_noise_logpdf`.
Its Monte Carlo data is built by :mod:`quadest.simulation.upf_benchmark_data`.
"""

from __future__ import annotations

import math

import numpy as np

from quadest.config.ranges import require_positive
from quadest.config.settings import DataSettings
from quadest.models.base import FilterModel


class UPFBenchmarkModel(FilterModel):
    """The UPF paper's scalar model (see the module docstring), analytic Jacobians
    ``F = 0.5``, ``H = 0.4 x`` (t ≤ switch_time) or ``0.5``."""

    name = "upf_benchmark"
    n, m, nu = 1, 1, 1
    state_names, state_units, measurement_names = ("x",), ("-",), ("y",)

    def __init__(
        self,
        Q: float,
        R: float,
        gamma_shape: float = 3.0,
        gamma_rate: float = 2.0,
        switch_time: float = 30.0,
        dt: float = 1.0,
        batch_size: int = 1,
    ) -> None:
        self.Q, self.R = np.array([[Q]]), np.array([[R]])
        self.gamma_shape, self.gamma_rate, self.switch_time = float(gamma_shape), float(gamma_rate), float(switch_time)
        self._log_norm = self.gamma_shape * math.log(self.gamma_rate) - math.lgamma(self.gamma_shape)
        self.dt, self.batch_size = dt, batch_size

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        t = u[:, None, :1] + 1.0
        return 1.0 + np.sin(0.04 * np.pi * t) + 0.5 * x

    def _first_regime(self, u: np.ndarray) -> np.ndarray:
        return (u[:, None, :1] <= self.switch_time)[..., None]  # (B, 1, 1, 1) against (B, K, m, n)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.where(u[:, None, :1] <= self.switch_time, 0.2 * x * x, 0.5 * x - 2.0)

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.full((x.shape[0], 1, 1), 0.5)

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.H_points(x[:, None, :], u)[:, 0]

    def F_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.full((*x.shape[:2], 1, 1), 0.5)

    def H_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.where(self._first_regime(u), 0.4 * x[..., None], 0.5)

    def sample_process_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        """Gamma(shape, rate) draws, shape ``(*size, 1)``."""
        return rng.gamma(self.gamma_shape, 1.0 / self.gamma_rate, (*size, 1))

    def process_noise_logpdf(self, w: np.ndarray) -> np.ndarray:
        """``log Gamma(w; shape, rate)``; −∞ for ``w ≤ 0`` (outside the support)."""
        v = w[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            logp = self._log_norm + (self.gamma_shape - 1.0) * np.log(v) - self.gamma_rate * v
        return np.where(v > 0, logp, -np.inf)


def validate_upf_benchmark(settings: DataSettings) -> None:
    """Range checks of ``model=upf_benchmark``."""
    m = settings.model
    for key in ("Q", "R", "gamma_shape", "gamma_rate", "P0"):
        require_positive(f"model.{key}", getattr(m, key))
