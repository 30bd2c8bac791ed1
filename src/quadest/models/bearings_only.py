"""Bearings-only tracking as in the EKF/UKF toolbox manual (Hartikainen, Solin & Särkkä 2011,
*Optimal filtering with Kalman filters and smoothers: a manual for the Matlab toolbox EKF/UKF*,
v1.3, §3.6 "Demonstration: Bearings Only Tracking"): state ``x = (x, y, ẋ, ẏ)``, the filters'
dynamics the discretised Wiener velocity model (the manual's eqs for ``A`` and ``Q``),

    x_k = A x_{k−1} + q_{k−1},   A = [[I, Δt I], [0, I]],
    Q = q [[Δt³/3 I, Δt²/2 I], [Δt²/2 I, Δt I]],

and sensor ``i`` at ``s^i`` measuring the bearing ``θ^i_k = atan2(y_k − s^i_y, x_k − s^i_x) + r^i_k``,
``r^i_k ~ N(0, σ²)``, with the Jacobian of the manual's eq. (bot_dx): ``∂θ^i/∂x = −(y − s^i_y)/ρ²``,
``∂θ^i/∂y = (x − s^i_x)/ρ²``, ``ρ²`` the squared range (the manual's printed matrix after that
equation has its two columns swapped; the partial derivatives themselves are used here).

A bearing residual is wrapped to (−π, π] (:meth:`BearingsOnlyModel.measurement_residual`), so a
bearing just across ±π from its prediction is a small residual, not ≈ 2π. The derived error
``position`` is ``|p − p̂|``, the 2-D position error: its RMSE over a run is the manual's
``sqrt(mean((X₁ − M₁)² + (X₂ − M₂)²))``.

The truth (a turning target, not this model) is simulated by
:mod:`quadest.simulation.bearings_only_data`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.models.base import FilterModel
from quadest.models.wiener_velocity import constant_velocity_plane
from quadest.quadrotor.kinematics import wrap_angle


@dataclass
class BearingsOnlyModelConf:
    """``model=bearings_only``: the toolbox manual's bearings-only tracking (module docstring of
    :mod:`quadest.models.bearings_only`). Sensors at ``(sensor_x[i], sensor_y[i])`` measure bearings
    with standard deviation ``bearing_std`` (rad); ``q`` is the spectral density of the filters'
    Wiener velocity model per axis; every filter starts from ``m0`` with covariance ``diag(P0)``;
    the true target starts at ``x0`` and turns at rate ``turn_angle / turn_steps / Δt`` (plus
    ``turn_rate_std`` times a standard normal per step) on ``turn_steps`` steps from each of
    ``turn_starts`` (step 1 is the first transition), going straight elsewhere."""

    name: str = "bearings_only"
    sensor_x: list[float] = field(default_factory=lambda: [-1.0, 1.0])
    sensor_y: list[float] = field(default_factory=lambda: [-2.0, 1.0])
    bearing_std: float = 0.05
    q: float = 0.1
    m0: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0])
    P0: list[float] = field(default_factory=lambda: [0.1, 0.1, 10.0, 10.0])
    x0: list[float] = field(default_factory=lambda: [0.0, 0.0, 1.0, 0.0])
    turn_starts: list[int] = field(default_factory=lambda: [50, 200, 350])
    turn_steps: int = 51
    turn_angle: float = float(np.pi / 2)
    turn_rate_std: float = 0.01


class BearingsOnlyModel(FilterModel):
    """The manual's filter model (module docstring), bound to ``batch_size`` runs."""

    name = "bearings_only"
    n, nu = 4, 0
    state_names, state_units = ("x", "y", "vx", "vy"), ("m", "m", "m/s", "m/s")
    derived_error_names, derived_error_units = ("position",), ("m",)

    def __init__(self, dt: float, q: float, bearing_std: float, sensors: np.ndarray, batch_size: int) -> None:
        self.dt, self.batch_size = float(dt), int(batch_size)
        self.sensors_xy = np.asarray(sensors, dtype=float).reshape(-1, 2)
        self.m = self.sensors_xy.shape[0]
        self.measurement_names = tuple(f"bearing_{i + 1}" for i in range(self.m))
        self.A, self.Q = constant_velocity_plane(q, self.dt)
        self.R = float(bearing_std) ** 2 * np.eye(self.m)

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return x @ self.A.T

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        dx = x[..., None, 0] - self.sensors_xy[:, 0]
        dy = x[..., None, 1] - self.sensors_xy[:, 1]
        return np.arctan2(dy, dx)

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.A, (x.shape[0], 4, 4)).copy()

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        dx = x[:, None, 0] - self.sensors_xy[:, 0]
        dy = x[:, None, 1] - self.sensors_xy[:, 1]
        rho2 = dx**2 + dy**2
        H = np.zeros((x.shape[0], self.m, 4))
        H[:, :, 0] = -dy / rho2
        H[:, :, 1] = dx / rho2
        return H

    def measurement_residual(self, z: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """The bearing difference wrapped to (−π, π]."""
        return wrap_angle(z - predicted)

    def derived_errors(self, estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
        """The 2-D position error ``|p − p̂|`` (B, 1): its per-run RMSE is the manual's."""
        return np.linalg.norm(estimate[..., :2] - truth[..., :2], axis=-1, keepdims=True)
