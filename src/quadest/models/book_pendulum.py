"""The noisy pendulum of Särkkä & Svensson (2023, *Bayesian Filtering and Smoothing*, 2nd ed.,
Example 5.1 / 7.6): state ``x = (α, α̇)``, Euler-discretised with step ``Δt``,

    x_k = (α + α̇ Δt,  α̇ − g sin(α) Δt) + q,   q ~ N(0, Q),
    Q = q_c [[Δt³/3, Δt²/2], [Δt²/2, Δt]],
    y_k = sin(α_k) + r,   r ~ N(0, R),

with analytic Jacobians ``F = [[1, Δt], [−g cos(α) Δt, 1]]`` and ``H = [cos α, 0]``.
"""

from __future__ import annotations

import numpy as np

from quadest.models.base import FilterModel
from quadest.models.wiener_velocity import wiener_velocity_block


class BookPendulumModel(FilterModel):
    """The book's pendulum (module docstring), bound to ``batch_size`` runs."""

    name = "book_pendulum"
    n, m, nu = 2, 1, 0
    state_names, state_units, measurement_names = ("angle", "rate"), ("rad", "rad/s"), ("sin_angle",)

    def __init__(self, dt: float, g: float, q_c: float, R: float, batch_size: int) -> None:
        self.dt, self.g, self.batch_size = float(dt), float(g), int(batch_size)
        self.Q = wiener_velocity_block(q_c, dt)
        self.R = np.array([[float(R)]])

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        a, w = x[..., 0], x[..., 1]
        return np.stack([a + w * self.dt, w - self.g * np.sin(a) * self.dt], axis=-1)

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.sin(x[..., :1])

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        F = np.zeros((x.shape[0], 2, 2))
        F[:, 0, 0] = F[:, 1, 1] = 1.0
        F[:, 0, 1] = self.dt
        F[:, 1, 0] = -self.g * np.cos(x[:, 0]) * self.dt
        return F

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        H = np.zeros((x.shape[0], 1, 2))
        H[:, 0, 0] = np.cos(x[:, 0])
        return H
