"""The reentry vehicle of Julier & Uhlmann (2004, "Unscented filtering and nonlinear estimation",
Proc. IEEE 92(3), §VII) in the setting of the EKF/UKF toolbox manual (Hartikainen, Solin & Särkkä,
*Optimal filtering with Kalman filters and smoothers*, v1.3, 2011, §3 "Demonstration: Reentry
Vehicle Tracking"), which takes the corrections of Julier & Uhlmann's erratum (the ballistic
parameter's noise 10⁻⁶ instead of 0).

State ``x = (x1, x2, x3, x4, x5)``: position (km) and velocity (km/s) in the plane of the orbit,
and the log of the ballistic coefficient relative to ``β0``. With

    R = √(x1² + x2²),  V = √(x3² + x4²),  β = β0 exp(x5),
    D = β exp((R0 − R)/H0) V,  G = −Gm0 / R³,

the dynamics are ``ẋ1 = x3``, ``ẋ2 = x4``, ``ẋ3 = D x3 + G x1 + v1``, ``ẋ4 = D x4 + G x2 + v2``,
``ẋ5 = v3``, discretised with one Euler step of ``Δt``:

    x_k = x_{k−1} + Δt ẋ(x_{k−1}) + L w_{k−1},   w ~ N(0, Qc Δt),   L = [0₂ₓ₃; I₃],

so the process noise enters the last three states through the input matrix ``L`` and the
state-space noise covariance ``Q = L Qc Lᵀ Δt`` has rank 3 of 5. A radar at ``(sx, sy)`` measures

    r = √((x1 − sx)² + (x2 − sy)²) + q1,   θ = atan2(x2 − sy, x1 − sx) + q2,

with ``q ~ N(0, diag(σr², σθ²))``; the bearing's residual is wrapped to (−π, π].

Jacobians (analytic; the manual's printed ones carry misprints — ``∂β/∂x5 = β/R`` for ``β`` and
``∂r/∂x1 = x1/r`` for ``(x1 − sx)/r`` — so these are derived afresh and held to central
differences in ``tests/test_reentry.py``): with ``E = exp((R0 − R)/H0)``,

    ∂D/∂x1 = −D x1/(R H0),  ∂D/∂x2 = −D x2/(R H0),  ∂D/∂x3 = β E x3/V,  ∂D/∂x4 = β E x4/V,
    ∂D/∂x5 = D,  ∂G/∂xi = 3 Gm0 xi / R⁵ (i = 1, 2),

``F = I + Δt J`` with ``J`` the Jacobian of ``ẋ``; ``∂r/∂(x1, x2) = (dx, dy)/r`` and
``∂θ/∂(x1, x2) = (−dy, dx)/r²`` with ``(dx, dy) = (x1 − sx, x2 − sy)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadest.models.base import FilterModel
from quadest.quadrotor.kinematics import wrap_angle

NOISE_INPUT = np.vstack([np.zeros((2, 3)), np.eye(3)])
"""``L``: the three process-noise inputs enter the two velocities and the ballistic parameter."""


@dataclass
class ReentryModelConf:
    """``model=reentry`` (:mod:`quadest.models.reentry`): the constants ``beta0``, ``H0`` (km),
    ``Gm0`` (km³/s²), ``R0`` (km); the radar position ``radar`` (km) and its noise ``sigma_range``
    (km), ``sigma_bearing`` (rad); the spectral densities of the three noise inputs, ``q_c`` for the
    filters and ``truth_q_c`` for the simulated truth (``Q = diag(q_c) Δt``); the truth's initial
    mean ``x0`` and variances ``x0_var``; every filter's start ``m0``, ``diag(P0)``."""

    name: str = "reentry"
    beta0: float = -0.59783
    H0: float = 13.406
    Gm0: float = 3.9860e5
    R0: float = 6374.0
    radar: list[float] = field(default_factory=lambda: [6374.0, 0.0])
    sigma_range: float = 1.0e-3
    sigma_bearing: float = 0.17e-3
    q_c: list[float] = field(default_factory=lambda: [2.4064e-4, 2.4064e-4, 1.0e-5])
    truth_q_c: list[float] = field(default_factory=lambda: [2.4064e-4, 2.4064e-4, 0.0])
    x0: list[float] = field(default_factory=lambda: [6500.4, 349.14, -1.8093, -6.7967, 0.6932])
    x0_var: list[float] = field(default_factory=lambda: [1.0e-6, 1.0e-6, 1.0e-6, 1.0e-6, 0.0])
    m0: list[float] = field(default_factory=lambda: [6500.4, 349.14, -1.8093, -6.7967, 0.0])
    P0: list[float] = field(default_factory=lambda: [1.0e-6, 1.0e-6, 1.0e-6, 1.0e-6, 1.0])


class ReentryModel(FilterModel):
    """The reentry vehicle (module docstring), bound to ``batch_size`` runs.

    Args:
        dt: the Euler step Δt (s), the sample period.
        beta0, H0, Gm0, R0: the constants of the drag and gravity terms.
        radar: (sx, sy), the radar's position (km).
        sigma_range, sigma_bearing: the measurement noise's standard deviations (km, rad).
        q_c: (3,) spectral densities of the noise inputs; ``Q = L diag(q_c) Lᵀ Δt``.
        batch_size: runs the model is bound to.
    """

    name = "reentry"
    n, m, nu = 5, 2, 0
    state_names = ("x1", "x2", "x3", "x4", "x5")
    state_units = ("km", "km", "km/s", "km/s", "1")
    measurement_names = ("range", "bearing")
    derived_error_names = ("position",)
    derived_error_units = ("km",)

    def __init__(
        self,
        dt: float,
        beta0: float,
        H0: float,
        Gm0: float,
        R0: float,
        radar: tuple[float, float],
        sigma_range: float,
        sigma_bearing: float,
        q_c: np.ndarray,
        batch_size: int,
    ) -> None:
        self.dt, self.beta0, self.H0, self.Gm0, self.R0 = float(dt), float(beta0), float(H0), float(Gm0), float(R0)
        self.radar = np.array(radar, dtype=float)
        self.batch_size = int(batch_size)
        self.Q = NOISE_INPUT @ np.diag(np.asarray(q_c, dtype=float)) @ NOISE_INPUT.T * self.dt
        self.R = np.diag([float(sigma_range) ** 2, float(sigma_bearing) ** 2])

    @property
    def state_groups(self) -> dict[str, tuple[str, ...]]:
        """Position, velocity and the ballistic parameter."""
        return {"position": ("x1", "x2"), "velocity": ("x3", "x4"), "ballistic": ("x5",)}

    def _forces(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """``R, V, β exp((R0 − R)/H0), D, G`` at states ``x`` (..., 5)."""
        R = np.hypot(x[..., 0], x[..., 1])
        V = np.hypot(x[..., 2], x[..., 3])
        drag_per_speed = self.beta0 * np.exp(x[..., 4]) * np.exp((self.R0 - R) / self.H0)
        return R, V, drag_per_speed, drag_per_speed * V, -self.Gm0 / R**3

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        _, _, _, D, G = self._forces(x)
        rate = np.stack(
            [x[..., 2], x[..., 3], D * x[..., 2] + G * x[..., 0], D * x[..., 3] + G * x[..., 1], np.zeros_like(D)],
            axis=-1,
        )
        return x + self.dt * rate

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        dx, dy = x[..., 0] - self.radar[0], x[..., 1] - self.radar[1]
        return np.stack([np.hypot(dx, dy), np.arctan2(dy, dx)], axis=-1)

    def measurement_residual(self, z: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """``z − ẑ`` with the bearing's difference wrapped to (−π, π]."""
        r = z - predicted
        return np.concatenate([r[..., :1], wrap_angle(r[..., 1:])], axis=-1)

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        R, V, drag_per_speed, D, G = self._forces(x)
        x1, x2, x3, x4 = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
        dD = np.stack(
            [-D * x1 / (R * self.H0), -D * x2 / (R * self.H0), drag_per_speed * x3 / V, drag_per_speed * x4 / V, D],
            axis=-1,
        )
        dG = np.stack([3.0 * self.Gm0 * x1 / R**5, 3.0 * self.Gm0 * x2 / R**5], axis=-1)
        J = np.zeros((x.shape[0], 5, 5))
        J[:, 0, 2] = J[:, 1, 3] = 1.0
        J[:, 2] = dD * x3[:, None]
        J[:, 3] = dD * x4[:, None]
        J[:, 2, :2] += dG * x1[:, None]
        J[:, 3, :2] += dG * x2[:, None]
        J[:, 2, 0] += G
        J[:, 3, 1] += G
        J[:, 2, 2] += D
        J[:, 3, 3] += D
        return np.eye(5)[None] + self.dt * J

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        dx, dy = x[:, 0] - self.radar[0], x[:, 1] - self.radar[1]
        r2 = dx**2 + dy**2
        r = np.sqrt(r2)
        H = np.zeros((x.shape[0], 2, 5))
        H[:, 0, 0], H[:, 0, 1] = dx / r, dy / r
        H[:, 1, 0], H[:, 1, 1] = -dy / r2, dx / r2
        return H

    def derived_errors(self, estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
        """The position error's length ``|p̂ − p|`` (km): its RMSE over time is the manual's
        ``sqrt(mean_k |p_k − p̂_k|²)``."""
        return np.linalg.norm(estimate[..., :2] - truth[..., :2], axis=-1, keepdims=True)
