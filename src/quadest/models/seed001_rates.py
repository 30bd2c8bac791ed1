"""``model=seed001_rates``: seed 001's angular-rate filter on the shared quadrotor.

Seed 001 (Li & Liang 2015, §1 and §3.1) filters the body rates ``x = (p, q, r)`` of an OS4
quadrotor with the rotor speeds as input and the gyro as measurement, sample period 20 ms,
process and measurement noise variances 0.1 (rad/s)², on a backstepping flight from a disturbed
attitude back to level. Here:

- transition: one Euler step of the OS4 rotational dynamics (Bouabdallah's Euler equation with
  the rotor gyroscopic term and rotational drag, :func:`quadest.quadrotor.dynamics.body_angular_accel`),
  ``x_k = x_{k−1} + T ω̇(x_{k−1}, Ω_{k−1})``, the input the true rotor speeds at the previous sample;
- measurement: the gyro, ``z = x + n``, ``n ~ N(0, R)``, white noise from the ``measurement`` stream;
- truth, ``model.truth`` (:data:`TRUTHS`), both started at the flown rates and driven by the rotor
  speeds Ω of the shared quadrotor flown by the backstepping controller through the configured
  scenario (``experiment=seed001_rates``: ``attitude_steps``, a manoeuvre of ours — the seed only says
  "from a disturbed attitude back to level"):

  - ``own_model`` (default): the seed's model itself, ``x_k = f(x_{k−1}, Ω_{k−1}) + w_k`` with
    ``w_k ~ N(0, Q)`` from the ``process`` stream (§3.1: process-noise variance Q = 0.1 (rad/s)²).
    Every filter assumes the same ``Q`` and ``R`` the truth is drawn with, so the EKF is the Bayes
    filter up to linearisation and the PCRLB of the filter model is a true bound here
    (:mod:`quadest.evaluation.pcrlb`);
  - ``flown``: the flown manoeuvre, ``x_k = f(x_{k−1}, Ω_{k−1})`` without process noise: the same
    Euler step driven by the same deterministic rotor-speed command, the backstepping controller's
    output along the scenario. This is §3.1's reading "the quadrotor model combined with the
    backstepping nonlinear control system gives the complete simulated attitude data": the truth
    is the flight, and only the filters' assumed ``Q`` is a tuning value. The truth then does not
    follow the filter model's noise, so the PCRLB column is the filter model's recursion, a
    reference rather than a floor.

The truth and the Monte Carlo data are built by :mod:`quadest.simulation.seed001_rates_data`.
"""

from __future__ import annotations

import numpy as np

from quadest.config.ranges import require_positive
from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.base import FilterModel
from quadest.models.config_checks import validate_quadrotor
from quadest.quadrotor.dynamics import body_angular_accel, body_rate_jacobian, rotor_inputs
from quadest.quadrotor.params import QuadrotorParams

TRUTHS = ("own_model", "flown")  # model.truth: the filter model with N(0, Q) noise, or the flight without it
RATES = slice(9, 12)  # body rates p, q, r in the 16-state truth
ROTORS = slice(12, 16)


class RateModel(FilterModel):
    """Body rates ``(p, q, r)`` with rotor speeds (4) as input and a gyro measurement."""

    name = "seed001_rates"
    n, m, nu = 3, 3, 4
    state_names = ("p", "q", "r")
    state_units = ("rad/s", "rad/s", "rad/s")
    measurement_names = ("gyro_x", "gyro_y", "gyro_z")

    def __init__(self, params: QuadrotorParams, dt: float, Q: np.ndarray, R: np.ndarray, batch_size: int) -> None:
        self.params, self.dt = params, dt
        self.Q, self.R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
        self.batch_size = batch_size

    def f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        U, omega_r = rotor_inputs(self.params, u)
        return x + self.dt * body_angular_accel(self.params, x, U[:, None, 1:4], omega_r[:, None])

    def h(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return x.copy()

    def F_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``I + T ∂ω̇/∂ω`` at every point (B, K, 3, 3), from the Euler equation of
        :func:`~quadest.quadrotor.dynamics.body_angular_accel`."""
        omega_r = rotor_inputs(self.params, u)[1][:, None]  # (B, 1)
        return np.eye(3) + self.dt * body_rate_jacobian(self.params, x, omega_r)

    def F_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self.F_points(x[:, None, :], u)[:, 0]

    def H_analytic(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.eye(3), (x.shape[0], 3, 3)).copy()

    def H_points(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.eye(3), (*x.shape[:2], 3, 3)).copy()


def validate_seed001_rates(settings: DataSettings) -> None:
    """Range checks of ``model=seed001_rates``: the truth option, the quadrotor's, plus the filters'
    noise."""
    if settings.model.truth not in TRUTHS:
        raise ConfigError("model.truth", settings.model.truth, f"one of {list(TRUTHS)}")
    validate_quadrotor(settings)
    for key in ("Q", "R", "P0"):
        require_positive(f"model.{key}", getattr(settings.model, key))
